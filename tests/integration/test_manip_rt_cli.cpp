// The manip_rt executable's exit codes (skipped when the app is not built).
#include <catch2/catch.hpp>

#include <unistd.h>

#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "fixtures.hpp"
#include "manip/version.hpp"

namespace {
const std::string kApp = std::string(MANIP_BINARY_DIR) + "/apps/manip_rt";

int run(const std::string& args, std::string* output = nullptr) {
  return manip::testutil::run_command("cd " + std::string(MANIP_SOURCE_DIR) + " && " + kApp + " " + args, output);
}
}  // namespace

TEST_CASE("manip_rt: exit codes of the executable", "[cli]") {
  if (!std::filesystem::exists(kApp)) {
    WARN("manip_rt not built: skipped (ninja manip_rt)");
    return;
  }
  std::string out;
  CHECK(run("--help", &out) == 0);
  CHECK(out.find("Exit codes") != std::string::npos);
  // the rows of common/exit_codes.hpp, by value (lab scripts test these numbers)
  CHECK(out.find("    9 real-time set-up failed") != std::string::npos);
  CHECK(out.find("    8 backend unavailable") != std::string::npos);
  CHECK(out.find("   10 LCM bus unavailable") != std::string::npos);
  CHECK(out.find("    9: --require-rt") != std::string::npos);
  // --backend can over SocketCAN: no AF_CAN here, or no can0 on a machine with CAN support
  {
    const std::string can_log =
        (std::filesystem::temp_directory_path() / ("manip_rt_can_" + std::to_string(::getpid()) + ".lcm")).string();
    CHECK(run("--backend can --force --out " + can_log, &out) == 8);
    CHECK(out.find("CAN bus 'bus_x' (can0)") != std::string::npos);
    std::filesystem::remove(can_log);  // the log is opened before the backend starts
  }
  CHECK(run("--no-such-flag", &out) == 2);
  CHECK(run("--backend serial --out /tmp/never.lcm", &out) == 2);
  {
    std::ifstream rt("/sys/kernel/realtime");
    int v = 0;
    if (!(rt >> v && v == 1)) {  // not a PREEMPT_RT kernel: refused up front
      CHECK(run("--realtime --require-rt --duration 0.1 --lcm-url none --quiet --out /tmp/never.lcm", &out) == 9);
      CHECK(out.find("PREEMPT_RT") != std::string::npos);
      CHECK_FALSE(std::filesystem::exists("/tmp/never.lcm"));
    }
  }

  const std::string bad = (std::filesystem::temp_directory_path() / ("manip_rt_bad_" + std::to_string(::getpid()) + ".yaml")).string();
  {
    std::ifstream in(std::string(MANIP_SOURCE_DIR) + "/config/rt.yaml");
    std::ostringstream os;
    os << in.rdbuf();
    std::ofstream o(bad);
    o << os.str() << "\nunexpected_section: 1\n";
  }
  CHECK(run("--config " + bad + " --out /tmp/never.lcm", &out) == 3);
  CHECK(out.find(bad + ":") != std::string::npos);
  CHECK(out.find("unexpected_section: unknown key") != std::string::npos);
  std::filesystem::remove(bad);

  const std::string log = (std::filesystem::temp_directory_path() / ("manip_rt_cli_" + std::to_string(::getpid()) + ".lcm")).string();
  CHECK(run("--duration 2 --lcm-url none --quiet --force --out " + log, &out) == 0);
  CHECK(std::filesystem::file_size(log) > 1000000u);
  CHECK(run("--duration 2 --lcm-url none --quiet --out " + log, &out) == 6);  // exists, no --force
  // SIGINT during a paced run: stopped safely, log closed, exit 130
  const std::string app = kApp;
  const std::string cmd = "cd " + std::string(MANIP_SOURCE_DIR) + " && timeout --preserve-status -s INT 1 " + app +
                          " --realtime --lcm-url none --quiet --force --out " + log + " >/dev/null 2>&1";
  const int st = std::system(cmd.c_str());
  CHECK((WIFEXITED(st) ? WEXITSTATUS(st) : -1) == 130);
  CHECK(std::filesystem::file_size(log) > 100000u);
  std::filesystem::remove(log);
}

TEST_CASE("manip_rt: SIGHUP, SIGPIPE, bad --duration, failed bus start (issue 9)", "[cli][hardening]") {
  if (!std::filesystem::exists(kApp)) {
    WARN("manip_rt not built: skipped (ninja manip_rt)");
    return;
  }
  std::string out;
  CHECK(run("--help", &out) == 0);
  CHECK(out.find("SIGHUP") != std::string::npos);
  for (const char* d : {"nan", "-1", "inf", "abc"}) {
    INFO("--duration " << d);
    CHECK(run(std::string("--duration ") + d + " --lcm-url none --quiet --out /tmp/never.lcm", &out) == 2);
    CHECK(out.find("--duration") != std::string::npos);
    CHECK_FALSE(std::filesystem::exists("/tmp/never.lcm"));
  }
  const std::string app = kApp;
  const std::string log =
      (std::filesystem::temp_directory_path() / ("manip_rt_hup_" + std::to_string(::getpid()) + ".lcm")).string();
  // A bus that cannot start leaves no stub log behind (the rerun is not blocked).
  CHECK(run("--realtime --duration 1 --lcm-url nosuch://x --quiet --out " + log, &out) == 10);
  CHECK_FALSE(std::filesystem::exists(log));
  // SIGHUP (closed terminal, dropped ssh session): orderly stop, exit 130, named.
  const std::string errf = log + ".err";
  std::string cmd = "cd " + std::string(MANIP_SOURCE_DIR) + " && timeout --preserve-status -s HUP 1 " + app +
                    " --realtime --lcm-url none --quiet --force --out " + log + " >/dev/null 2>" + errf;
  int st = std::system(cmd.c_str());
  CHECK((WIFEXITED(st) ? WEXITSTATUS(st) : -1) == 130);
  {
    std::ifstream in(errf);
    std::ostringstream os;
    os << in.rdbuf();
    CHECK(os.str().find("interrupted by SIGHUP") != std::string::npos);
  }
  CHECK(std::filesystem::file_size(log) > 100000u);
  // SIGPIPE: stderr into a pipe whose reader quits after one line; the session
  // runs to its end (1 s = 4000 cycles) and exits 0.
  cmd = "cd " + std::string(MANIP_SOURCE_DIR) + " && bash -c '" + app +
        " --realtime --duration 1 --lcm-url none --force --out " + log +
        " 2>&1 | head -1 >/dev/null; exit ${PIPESTATUS[0]}'";
  st = std::system(cmd.c_str());
  const int rc = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  INFO("exit " << rc);
  // 0, or 7 if this (shared, unisolated) machine made the paced loop latch an
  // overrun fault; before the fix: 141 (killed by SIGPIPE, log lost).
  CHECK((rc == 0 || rc == 7));
  CHECK(std::filesystem::file_size(log) > 4000u * 150u);
  std::filesystem::remove(log);
  std::filesystem::remove(errf);
}

namespace {
std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}
// Runs manip_rt from `cwd` with `env` prepended ("VAR=value ..."), stdout+stderr captured.
int run_in(const std::string& cwd, const std::string& env, const std::string& args, std::string* out) {
  return manip::testutil::run_command("cd " + cwd + " && env " + env + " " + kApp + " " + args, out);
}
}  // namespace

TEST_CASE("manip_rt: the common CLI (docs/cli.md): --out, --movements, -q, --version, deprecated aliases, --config search",
          "[cli]") {
  if (!std::filesystem::exists(kApp)) {
    WARN("manip_rt not built: skipped (ninja manip_rt)");
    return;
  }
  namespace fs = std::filesystem;
  const std::string dir = manip::testutil::temp_dir("manip_rt_common_cli");
  const std::string empty_home = dir + "/home";
  fs::create_directories(empty_home);
  fs::create_directories(dir + "/elsewhere");
  // No user or MANIP_CONFIG_DIR configuration: only the build tree's source config/ remains.
  const std::string clean = "-u MANIP_CONFIG_DIR -u XDG_CONFIG_HOME HOME=" + empty_home;
  std::string out;
  CHECK(run("--version", &out) == 0);
  CHECK(out == "manip_rt " + std::string(manip::kVersion) + "\n");

  // From a directory without config/: rt.yaml found (build tree -> source config/); -q: silent on success.
  CHECK(run_in(dir + "/elsewhere", clean, "--movements 2 --lcm-url none -q --out a.lcm", &out) == 0);
  CHECK(fs::file_size(dir + "/elsewhere/a.lcm") > 100000u);
  CHECK(out.empty());
  // Without -q the start line names the configuration it found.
  CHECK(run_in(dir + "/elsewhere", clean, "--movements 1 --lcm-url none --out b.lcm", &out) == 0);
  CHECK(out.find("config " + std::string(MANIP_SOURCE_DIR) + "/config/rt.yaml") != std::string::npos);
  CHECK(out.find("1 movements") != std::string::npos);

  // $MANIP_CONFIG_DIR first: an rt.yaml there with another session id wins.
  fs::create_directories(dir + "/lab");
  {
    std::string y = read_text(std::string(MANIP_SOURCE_DIR) + "/config/rt.yaml");
    const auto at = y.find("session_id:");
    REQUIRE(at != std::string::npos);
    const auto eol = y.find('\n', at);
    y.replace(at, eol - at, "session_id: lab-copy");
    std::ofstream(dir + "/lab/rt.yaml") << y;
  }
  CHECK(run_in(dir + "/elsewhere", clean + " MANIP_CONFIG_DIR=" + dir + "/lab", "--movements 1 --lcm-url none --out c.lcm",
               &out) == 0);
  CHECK(out.find("config " + dir + "/lab/rt.yaml") != std::string::npos);
  // A bare --config name is searched the same way; a missing one: exit 3 naming every place searched.
  CHECK(run_in(dir + "/elsewhere", clean + " MANIP_CONFIG_DIR=" + dir + "/lab", "--config rt.yaml --movements 1 --lcm-url none -q --out d.lcm",
               &out) == 0);
  CHECK(run_in(dir + "/elsewhere", clean + " MANIP_CONFIG_DIR=" + dir + "/lab", "--config nosuch.yaml --lcm-url none --out e.lcm",
               &out) == 3);
  CHECK(out.find("nosuch.yaml: configuration file not found (searched: ./, " + dir + "/lab, " + empty_home +
                 "/.config/manip") != std::string::npos);
  CHECK_FALSE(fs::exists(dir + "/elsewhere/e.lcm"));

  // Deprecated aliases: still work, one line each naming the replacement (also with -q: it is a warning).
  CHECK(run_in(dir + "/elsewhere", clean, "--trials 1 --lcm-url none -q --log f.lcm", &out) == 0);
  CHECK(out.find("manip_rt: --trials is deprecated; use --movements\n") != std::string::npos);
  CHECK(out.find("manip_rt: --log is deprecated; use --out\n") != std::string::npos);
  CHECK(fs::file_size(dir + "/elsewhere/f.lcm") > 100000u);
  // ... checked like their replacement, and never both at once.
  CHECK(run_in(dir + "/elsewhere", clean, "--trials 0 --lcm-url none --out g.lcm", &out) == 2);
  CHECK(out.find("--trials") != std::string::npos);
  CHECK(run_in(dir + "/elsewhere", clean, "--movements 1 --lcm-url none --out g.lcm --log h.lcm", &out) == 2);
  CHECK(out.find("excludes") != std::string::npos);
  CHECK(run_in(dir + "/elsewhere", clean, "--movements 0 --lcm-url none --out g.lcm", &out) == 2);
  CHECK(run_in(dir + "/elsewhere", clean, "--duration nan --lcm-url none --out g.lcm", &out) == 2);
  CHECK_FALSE(fs::exists(dir + "/elsewhere/g.lcm"));
  CHECK_FALSE(fs::exists(dir + "/elsewhere/h.lcm"));
  // An existing log is kept without --force (exit 6), replaced with it.
  const auto before = fs::file_size(dir + "/elsewhere/a.lcm");
  CHECK(run_in(dir + "/elsewhere", clean, "--movements 1 --lcm-url none -q --out a.lcm", &out) == 6);
  CHECK(fs::file_size(dir + "/elsewhere/a.lcm") == before);
}

TEST_CASE("manip_rt: rt.yaml's neuromech arm_config is found from any directory", "[cli]") {
  if (!std::filesystem::exists(kApp)) {
    WARN("manip_rt not built: skipped (ninja manip_rt)");
    return;
  }
  namespace fs = std::filesystem;
  const std::string dir = manip::testutil::temp_dir("manip_rt_arm_config");
  std::string y = read_text(std::string(MANIP_SOURCE_DIR) + "/config/rt.yaml");
  const auto at = y.find("model: linear");
  REQUIRE(at != std::string::npos);
  y.replace(at, std::string("model: linear").size(), "model: neuromech");
  fs::create_directories(dir + "/lab");
  std::ofstream(dir + "/lab/rt.yaml") << y;  // arm_config: config/arm_model.yaml, as packaged
  fs::create_directories(dir + "/home");
  std::string out;
  // cwd has no config/: the file name is found on the search path (here the build tree's source config/).
  CHECK(run_in(dir, "-u MANIP_CONFIG_DIR -u XDG_CONFIG_HOME HOME=" + dir + "/home",
               "--config lab/rt.yaml --duration 0.05 --lcm-url none -q --out n.lcm", &out) == 0);
  INFO(out);
  CHECK(fs::exists(dir + "/n.lcm"));
  // Beside rt.yaml wins over the search path; a broken one there is reported as a configuration error.
  std::ofstream(dir + "/lab/arm_model.yaml") << "not: [valid\n";
  CHECK(run_in(dir, "-u MANIP_CONFIG_DIR -u XDG_CONFIG_HOME HOME=" + dir + "/home",
               "--config lab/rt.yaml --duration 0.05 --lcm-url none -q --out m.lcm", &out) == 3);
  CHECK(out.find("configuration error: lab/arm_model.yaml:") != std::string::npos);
}

TEST_CASE("manip_rt log shorter than one trial: estimate_impedance prints the log's session, not empty fields (issue 13)",
          "[cli]") {
  const std::string est = std::string(MANIP_BINARY_DIR) + "/apps/estimate_impedance";
  if (!std::filesystem::exists(kApp) || !std::filesystem::exists(est)) {
    WARN("manip_rt or estimate_impedance not built: skipped");
    return;
  }
  const std::string dir = manip::testutil::temp_dir("manip_rt_short_log");
  std::string out;
  REQUIRE(run("--duration 0.3 --lcm-url none -q --out " + dir + "/short.lcm", &out) == 0);
  // No trial completed in 0.3 s: nothing to estimate (exit 5), but the session is the log's.
  CHECK(manip::testutil::run_command(est + " " + dir + "/short.lcm --json " + dir + "/short.json", &out) == 5);
  CHECK(out.find("session sim-session-001, participant sim-001, source manip_rt/sim, 4000 Hz") != std::string::npos);
  CHECK(out.find("(not given)") == std::string::npos);
  const std::string j = read_text(dir + "/short.json");
  CHECK(j.find("\"session_id\": \"sim-session-001\"") != std::string::npos);
  CHECK(j.find("\"software_version\": \"" + std::string(manip::kVersion)) != std::string::npos);
}
