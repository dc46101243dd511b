// make_hidden_session run as a user would: exit codes of the common table
// (common/exit_codes.hpp), no overwrite without --force, and a log whose
// session message does not reveal what was hidden.
#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <sys/wait.h>

#include "fixtures.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/logging/session_stream.hpp"

namespace {

const std::string kHiddenApp = std::string(MANIP_BINARY_DIR) + "/apps/make_hidden_session";

int run_hidden(const std::string& args, const std::string& log) {
  const int st = std::system((kHiddenApp + " " + args + " >" + log + " 2>&1").c_str());
  REQUIRE(WIFEXITED(st));
  return WEXITSTATUS(st);
}

std::string slurp_text(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

struct SessionOnly final : manip::logging::SessionHandler {
  manip::session_t session{};
  int states{0};
  void on_session(const manip::session_t& m) override { session = m; }
  void on_state(const manip::state_t&) override { ++states; }
};

}  // namespace

TEST_CASE("make_hidden_session: exit codes, no overwrite without --force, nothing hidden in the session message") {
  REQUIRE(std::filesystem::exists(kHiddenApp));
  namespace ec = manip::exit_code;
  const std::string dir = manip::testutil::temp_dir("hidden_cli");
  const std::string out = dir + "/out.txt";
  const std::string small = "--movements 8 --reps 1 --noise none --hidden-seed 5 ";

  CHECK(run_hidden("--hidden mass:0.3 -o " + dir + "/a.lcm", out) == ec::kUsage);
  CHECK(slurp_text(out).find("--hidden 'mass:0.3': unknown mechanism 'mass'") != std::string::npos);
  CHECK(run_hidden("--hidden delay:2 -o " + dir + "/a.lcm", out) == ec::kUsage);  // seconds, not ms
  CHECK(run_hidden("--movements 4 -o " + dir + "/a.lcm", out) == ec::kUsage);     // 24 perturbed do not fit
  CHECK_FALSE(std::filesystem::exists(dir + "/a.lcm"));

  CHECK(run_hidden(small + "-o " + dir + "/clean.lcm", out) == ec::kOk);
  CHECK(run_hidden(small + "--hidden handle:0.3 --key " + dir + "/key.txt -o " + dir + "/h.lcm", out) == ec::kOk);
  CHECK(slurp_text(dir + "/key.txt").find("handle:0.3") != std::string::npos);
  // An existing output is kept without --force (exit 6) and replaced with it.
  const auto size = std::filesystem::file_size(dir + "/h.lcm");
  CHECK(run_hidden(small + "--hidden curl:40 -o " + dir + "/h.lcm", out) == ec::kOutput);
  CHECK(slurp_text(out).find("exists") != std::string::npos);
  CHECK(std::filesystem::file_size(dir + "/h.lcm") == size);

  SessionOnly clean, hidden;
  manip::logging::read_log(dir + "/clean.lcm", clean);
  manip::logging::read_log(dir + "/h.lcm", hidden);
  CHECK(hidden.states == clean.states);
  CHECK(hidden.session.config_yaml == clean.session.config_yaml);
  CHECK(hidden.session.session_id == clean.session.session_id);
  for (int i = 0; i < 2; ++i) CHECK(hidden.session.m_handle_kg[i] == clean.session.m_handle_kg[i]);
  CHECK(slurp_text(dir + "/h.lcm").find("hidden:") == std::string::npos);  // the key text is not in the log
}
