// The estimate_impedance executable's exit codes (common/exit_codes.hpp;
// skipped when the app is not built).
#include <catch2/catch.hpp>

#include <unistd.h>

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "fixtures.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"

using namespace manip;

namespace {
const std::string kApp = std::string(MANIP_BINARY_DIR) + "/apps/estimate_impedance";

int run(const std::string& args, std::string* output = nullptr) { return testutil::run_command(kApp + " " + args, output); }
}  // namespace

TEST_CASE("estimate_impedance: exit codes of the executable", "[cli]") {
  if (!std::filesystem::exists(kApp)) {
    WARN("estimate_impedance not built: skipped (ninja estimate_impedance)");
    return;
  }
  namespace ec = manip::exit_code;
  const auto dir = testutil::temp_dir("estimate_cli");
  const std::string good = dir + "/good.lcm";
  testutil::write_recorded(testutil::record(testutil::small_design(10), sim::table1_person()), good);
  auto bad_rec = testutil::record(testutil::small_design(10), sim::table1_person());
  bad_rec.session.sample_rate_hz = -1.0;
  testutil::write_recorded(bad_rec, dir + "/bad_session.lcm");
  std::ofstream(dir + "/unknown_key.yaml") << "hp_order: 5\nhp_ordr: 4\n";
  std::ofstream(dir + "/duplicate_key.yaml") << "hp_order: 5\nhp_order: 4\n";

  std::string out;
  CHECK(run("--help", &out) == ec::kOk);
  CHECK(out.find("Exit codes") != std::string::npos);
  CHECK(out.find("    5 nothing to compute") != std::string::npos);
  CHECK(out.find("5: no usable perturbed trial") != std::string::npos);
  CHECK(out.find("[default, recommended]") != std::string::npos);  // the method list comes from the registry

  CHECK(run(good + " -q --method paper-pooled", &out) <= ec::kPartial);
  CHECK(run(good + " --no-such-option", &out) == ec::kUsage);
  CHECK(run(good + " --method nope", &out) == ec::kUsage);
  CHECK(out.find("unknown method 'nope'") != std::string::npos);
  CHECK(run(good + " --config " + dir + "/unknown_key.yaml", &out) == ec::kConfig);
  CHECK(out.find("unknown_key.yaml:2: hp_ordr: unknown key") != std::string::npos);
  CHECK(run(good + " --config " + dir + "/duplicate_key.yaml", &out) == ec::kConfig);
  CHECK(run(good + " --config " + dir + "/missing.yaml", &out) == ec::kConfig);
  CHECK(run(dir + "/missing.lcm -q", &out) == ec::kInput);
  CHECK(run(dir + "/bad_session.lcm -q", &out) == ec::kInput);
  CHECK(out.find("bad_session.lcm: byte 0 (MANIP_SESSION): session message: sample_rate_hz") != std::string::npos);
  // One log unusable, the other still estimated and printed.
  CHECK(run(dir + "/bad_session.lcm " + good + " -q --method paper-pooled", &out) == ec::kInput);
  CHECK(out.find("paper-pooled: pooled fit") != std::string::npos);
  CHECK(run(good + " -q --method paper-pooled --json " + dir + "/no/such/dir/out.json", &out) == ec::kOutput);
}

TEST_CASE("estimate_impedance: --version, -q, --config searched like every program's (docs/cli.md)", "[cli]") {
  if (!std::filesystem::exists(kApp)) {
    WARN("estimate_impedance not built: skipped (ninja estimate_impedance)");
    return;
  }
  namespace ec = manip::exit_code;
  const auto dir = testutil::temp_dir("estimate_cli_common");
  const std::string good = dir + "/good.lcm";
  testutil::write_recorded(testutil::record(testutil::small_design(10), sim::table1_person()), good);
  std::filesystem::create_directories(dir + "/home");
  std::filesystem::create_directories(dir + "/lab");
  std::ofstream(dir + "/lab/mine.yaml") << "hp_ordr: 4\n";  // invalid: proves it is the file read
  const std::string env = "cd " + dir + " && env -u MANIP_CONFIG_DIR -u XDG_CONFIG_HOME HOME=" + dir + "/home ";
  std::string out;
  CHECK(testutil::run_command(kApp + " --version", &out) == ec::kOk);
  CHECK(out.rfind("estimate_impedance ", 0) == 0);
  // A bare name: $MANIP_CONFIG_DIR first (here the invalid file: exit 3 naming it).
  CHECK(testutil::run_command(env + "MANIP_CONFIG_DIR=" + dir + "/lab " + kApp + " good.lcm -q --config mine.yaml", &out) ==
        ec::kConfig);
  CHECK(out.find(dir + "/lab/mine.yaml:1: hp_ordr: unknown key") != std::string::npos);
  // The packaged default by name, from a directory without config/ (build tree: the source config/).
  CHECK(testutil::run_command(env + kApp + " good.lcm -q --method pem --config estimator.yaml", &out) <= ec::kPartial);
  // Nowhere: exit 3 naming every directory searched; nothing else read.
  CHECK(testutil::run_command(env + kApp + " good.lcm -q --config nosuch.yaml", &out) == ec::kConfig);
  CHECK(out.find("nosuch.yaml: configuration file not found (searched: ./, " + dir + "/home/.config/manip") !=
        std::string::npos);
  // -q: nothing on stderr on success (stdout carries the result).
  CHECK(testutil::run_command("(" + env + kApp + " good.lcm -q --method pem 2>&1 >/dev/null)", &out) == ec::kOk);
  CHECK(out.empty());
}
