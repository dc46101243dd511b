#pragma once
// Run options of the offline session tests: write `log_path` (replacing an
// old file), no LCM bus, nothing on stdout.
#include <string>

#include "manip/runtime/session.hpp"

inline manip::runtime::RunOptions offline_run_options(const std::string& log_path) {
  manip::runtime::RunOptions opt;
  opt.log_path = log_path;
  opt.overwrite_log = true;
  opt.lcm_url = "none";
  opt.quiet = true;
  return opt;
}
