// manip_sim's exit codes are the common table (common/exit_codes.hpp): the
// program is run as a user would, and each failure class maps to its code.
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

const std::string kApp = std::string(MANIP_BINARY_DIR) + "/apps/manip_sim";

int run(const std::string& args, const std::string& log) {
  const int st = std::system((kApp + " " + args + " >" + log + " 2>&1").c_str());
  REQUIRE(WIFEXITED(st));
  return WEXITSTATUS(st);
}

std::string text(const std::string& path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

}  // namespace

TEST_CASE("manip_sim: exit codes and messages follow the common table") {
  REQUIRE(std::filesystem::exists(kApp));
  namespace ec = manip::exit_code;
  const std::string dir = manip::testutil::temp_dir("manip_sim_cli");
  const std::string out = dir + "/out.txt";

  CHECK(run("--help", out) == ec::kOk);
  CHECK(text(out).find("3 configuration invalid") != std::string::npos);
  CHECK(text(out).find("6 output cannot be written") != std::string::npos);

  CHECK(run("--bogus-option", out) == ec::kUsage);
  CHECK(run("--human centaur -o " + dir + "/a.lcm", out) == ec::kUsage);
  CHECK(text(out).find("unknown human model 'centaur'") != std::string::npos);
  CHECK(run("--noise loud -o " + dir + "/a.lcm", out) == ec::kUsage);
  CHECK(run("--movements 10 -o " + dir + "/a.lcm", out) == ec::kUsage);  // 24 perturbed do not fit
  CHECK(text(out).find("do not fit") != std::string::npos);

  // A parameters file with an unknown key: file:line: key: reason, code 3.
  std::string yaml = text(std::string(MANIP_SOURCE_DIR) + "/config/arm_model.yaml");
  yaml.replace(yaml.find("  tau_s: 0.05"), 12, "  tau_s: 0.05\n  sigma: 2");
  const std::string bad = dir + "/arm.yaml";
  std::ofstream(bad) << yaml;
  CHECK(run("--human neuromech --arm-config " + bad + " -o " + dir + "/a.lcm", out) == ec::kConfig);
  CHECK(text(out).find(bad + ":112: noise.sigma: unknown key") != std::string::npos);

  // The log cannot be created (its directory is a file).
  std::ofstream(dir + "/file") << "x";
  CHECK(run("--movements 8 --reps 1 -o " + dir + "/file/s.lcm", out) == ec::kOutput);

  // A short session is written and reads back.
  CHECK(run("--movements 8 --reps 1 --noise none -o " + dir + "/s.lcm", out) == ec::kOk);
  struct Count final : manip::logging::SessionHandler {
    int states{0};
    void on_state(const manip::state_t&) override { ++states; }
  } c;
  manip::logging::read_log(dir + "/s.lcm", c);
  CHECK(c.states > 8 * 4000 * 3);
}
