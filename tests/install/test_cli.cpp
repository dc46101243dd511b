// common/cli.hpp: the --config search order, value validators and the
// exit-code rows, against hand-written expectations (docs/cli.md).
#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

#include "fixtures.hpp"
#include "manip/common/cli.hpp"
#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"

namespace fs = std::filesystem;
namespace cli = manip::cli;

namespace {
// Restores an environment variable when the test ends.
struct EnvGuard {
  std::string name, old;
  bool had;
  EnvGuard(const std::string& n, const char* value) : name(n), had(std::getenv(n.c_str()) != nullptr) {
    if (had) old = std::getenv(n.c_str());
    if (value) ::setenv(n.c_str(), value, 1); else ::unsetenv(n.c_str());
  }
  ~EnvGuard() {
    if (had) ::setenv(name.c_str(), old.c_str(), 1); else ::unsetenv(name.c_str());
  }
};
void touch(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
}
std::string first_line(const fs::path& p) {
  std::ifstream f(p);
  std::string l;
  std::getline(f, l);
  return l;
}
int parse(CLI::App& app, std::vector<std::string> args) {
  std::vector<const char*> argv{"prog"};
  for (auto& a : args) argv.push_back(a.c_str());
  const auto rc = cli::parse(app, static_cast<int>(argv.size()), argv.data());
  return rc ? *rc : -1;
}
}  // namespace

TEST_CASE("cli: --config search order: MANIP_CONFIG_DIR, then XDG_CONFIG_HOME/manip, then the build tree's source config") {
  const fs::path dir = manip::testutil::temp_dir("cli_search");
  touch(dir / "env" / "rt.yaml", "env");
  touch(dir / "xdg" / "manip" / "rt.yaml", "xdg");
  touch(dir / "xdg" / "manip" / "only_xdg.yaml", "xdg-only");
  const fs::path cwd = fs::current_path();
  fs::current_path(dir);  // nothing named rt.yaml here

  {
    EnvGuard e("MANIP_CONFIG_DIR", (dir / "env").c_str());
    EnvGuard x("XDG_CONFIG_HOME", (dir / "xdg").c_str());
    CHECK(first_line(cli::find_config("", "rt.yaml")) == "env");
    CHECK(first_line(cli::find_config("only_xdg.yaml", "rt.yaml")) == "xdg-only");
    const auto dirs = cli::config_search_path();
    REQUIRE(dirs.size() >= 3);
    CHECK(dirs[0] == dir / "env");
    CHECK(dirs[1] == dir / "xdg" / "manip");
    // This test runs from the build tree: the source config/ is the last resort.
    CHECK(dirs.back() == fs::path(MANIP_SOURCE_DIR) / "config");
  }
  {
    EnvGuard e("MANIP_CONFIG_DIR", nullptr);
    EnvGuard x("XDG_CONFIG_HOME", (dir / "xdg").c_str());
    CHECK(first_line(cli::find_config("", "rt.yaml")) == "xdg");
  }
  {
    EnvGuard e("MANIP_CONFIG_DIR", nullptr);
    EnvGuard x("XDG_CONFIG_HOME", (dir / "nothing").c_str());
    EnvGuard h("HOME", (dir / "nothing").c_str());
    // Found in the source tree's config/ (build-tree run), from any directory.
    CHECK(cli::find_config("", "arm_model.yaml") == (fs::path(MANIP_SOURCE_DIR) / "config" / "arm_model.yaml").string());
    // Nowhere: ConfigError (exit 3) naming the file and the places searched.
    try {
      (void)cli::find_config("", "no_such_file.yaml");
      FAIL("no error");
    } catch (const manip::ConfigError& err) {
      const std::string m = err.what();
      CHECK(m.find("no_such_file.yaml: configuration file not found") == 0);
      CHECK(m.find((dir / "nothing" / "manip").string()) != std::string::npos);
      CHECK(err.exit_code() == 3);
    }
    // A path with a directory part is taken as given, never searched.
    CHECK_THROWS_AS(cli::find_config("./rt.yaml", "rt.yaml"), manip::ConfigError);
    CHECK(cli::find_config((dir / "env" / "rt.yaml").string(), "x.yaml") == (dir / "env" / "rt.yaml").string());
  }
  fs::current_path(cwd);
}

TEST_CASE("cli: values are finite and in range, choices are what --help lists") {
  double gain = 1;
  std::string noise = "none";
  CLI::App app{"t", "prog"};
  app.add_option("--gain", gain)->check(cli::finite_range(0, 10));
  app.add_option("--noise", noise)->check(cli::one_of({"none", "realistic"}));
  CHECK(parse(app, {"--gain", "2.5", "--noise", "realistic"}) == -1);
  CHECK(gain == 2.5);
  CHECK(noise == "realistic");
  for (const char* bad : {"nan", "inf", "-inf", "11", "-0.1", "1x", ""}) {
    CLI::App a{"t", "prog"};
    double g = 1;
    a.add_option("--gain", g)->check(cli::finite_range(0, 10));
    INFO(bad);
    CHECK(parse(a, {"--gain", bad}) == manip::exit_code::kUsage);
  }
  CLI::App b{"t", "prog"};
  b.add_option("--noise", noise)->check(cli::one_of({"none", "realistic"}));
  CHECK(parse(b, {"--noise", "motor"}) == manip::exit_code::kUsage);
}

TEST_CASE("cli: exit-code rows come from the one table") {
  namespace ec = manip::exit_code;
  CHECK(cli::exit_code_table({ec::kOk, ec::kUsage, ec::kInternal}) ==
        "Exit codes (docs/exit-codes.md):\n    0 ok\n    2 usage error\n   70 internal error\n");
  CLI::App app{"t", "prog"};
  cli::add_version(app, "prog");
  cli::set_exit_codes(app, {ec::kOk});
  CHECK(app.get_footer().find("0 ok") != std::string::npos);
  CHECK(parse(app, {"--version"}) == ec::kOk);
  CHECK(parse(app, {"--no-such-flag"}) == ec::kUsage);
}

TEST_CASE("cli: a deprecated alias sets the same value, says what replaces it, and is refused with its replacement") {
  namespace ec = manip::exit_code;
  std::ostringstream err;
  auto* old_buf = std::cerr.rdbuf(err.rdbuf());
  struct Restore {
    std::streambuf* b;
    ~Restore() { std::cerr.rdbuf(b); }
  } restore{old_buf};
  {
    CLI::App app{"t", "prog"};
    std::string out;
    int n = 0;
    cli::add_out(app, out, "log");
    app.add_option("--movements", n)->check(CLI::Range(1, 10));
    cli::add_deprecated_alias(app, "--log", "--out", out);
    cli::add_deprecated_alias(app, "--trials", "--movements", n)->check(CLI::Range(1, 10));
    CHECK(parse(app, {"--log", "a.lcm", "--trials", "3"}) == -1);
    CHECK(out == "a.lcm");
    CHECK(n == 3);
    CHECK(err.str() == "prog: --log is deprecated; use --out\nprog: --trials is deprecated; use --movements\n");
  }
  err.str("");
  {
    CLI::App app{"t", "prog"};
    std::string out;
    cli::add_out(app, out, "log");
    cli::add_deprecated_alias(app, "--log", "--out", out);
    CHECK(parse(app, {"--out", "a.lcm", "--log", "b.lcm"}) == ec::kUsage);
  }
  {
    CLI::App app{"t", "prog"};
    int n = 0;
    app.add_option("--movements", n)->check(CLI::Range(1, 10));
    cli::add_deprecated_alias(app, "--trials", "--movements", n)->check(CLI::Range(1, 10));
    err.str("");
    CHECK(parse(app, {"--trials", "0"}) == ec::kUsage);
    CHECK(err.str().find("--trials") != std::string::npos);
    CHECK(n == 0);
  }
}
