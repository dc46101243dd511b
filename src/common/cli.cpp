#include "manip/common/cli.hpp"

#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <system_error>

#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/version.hpp"

// Baked in by the top-level CMakeLists.txt (install section) for this file only.
#ifndef MANIP_INSTALL_CONFIG_DIR
#define MANIP_INSTALL_CONFIG_DIR ""
#endif
#ifndef MANIP_BUILD_TREE
#define MANIP_BUILD_TREE ""
#endif
#ifndef MANIP_SOURCE_CONFIG_DIR
#define MANIP_SOURCE_CONFIG_DIR ""
#endif

namespace manip::cli {
namespace fs = std::filesystem;

void add_version(CLI::App& app, const std::string& app_name) {
  app.set_version_flag("--version", app_name + " " + std::string(kVersion), "print \"" + app_name + " <version>\" and exit");
}

CLI::Option* add_quiet(CLI::App& app, bool& quiet) {
  return app.add_flag("-q,--quiet", quiet, "only warnings and errors on stderr");
}

CLI::Option* add_out(CLI::App& app, std::string& out, const std::string& what) {
  return app.add_option("-o,--out", out, what + " (an existing file is kept unless --force)");
}

CLI::Option* add_force(CLI::App& app, bool& force) {
  return app.add_flag("--force", force, "replace an existing output file");
}

CLI::Option* add_movements(CLI::App& app, int& n, int min_n, int max_n, const std::string& what) {
  return app.add_option("--movements", n, what)->check(CLI::Range(min_n, max_n))->capture_default_str();
}

void add_pulse(CLI::App& app, double& duration_s, double& amplitude_n) {
  app.add_option("--pulse-duration", duration_s,
                 "perturbation pulse duration T_pert in s (default 0.15, paper §3.2; a shorter pulse shows a reflex's delay, docs/diagnosis.md)")
      ->check(CLI::Range(1e-3, 2.0))
      ->capture_default_str();
  app.add_option("--pulse-amplitude", amplitude_n, "perturbation pulse amplitude A_pert in N (default 15, paper §3.2; at most 30)")
      ->check(CLI::Range(0.0, 30.0))
      ->capture_default_str();
}

CLI::Option* add_config(CLI::App& app, std::string& config, const std::string& default_name, const std::string& what) {
  return app.add_option("--config", config,
                        what + " (default " + default_name +
                            ", searched in $MANIP_CONFIG_DIR, $XDG_CONFIG_HOME/manip, <prefix>/share/manip/config; "
                            "docs/cli.md)");
}

namespace {
std::optional<double> to_double(const std::string& s) {
  if (s.empty()) return std::nullopt;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end == s.c_str() || *end != '\0') return std::nullopt;
  return v;
}
}  // namespace

CLI::Validator finite() {
  return CLI::Validator(
      [](std::string& s) -> std::string {
        const auto v = to_double(s);
        if (!v) return "not a number: '" + s + "'";
        if (!std::isfinite(*v)) return "must be finite (got " + s + ")";
        return {};
      },
      "FINITE");
}

CLI::Validator finite_range(double lo, double hi) {
  std::ostringstream desc;
  desc << "[" << lo << ", " << hi << "]";
  return CLI::Validator(
      [lo, hi, d = desc.str()](std::string& s) -> std::string {
        const auto v = to_double(s);
        if (!v) return "not a number: '" + s + "'";
        if (!std::isfinite(*v)) return "must be finite (got " + s + ")";
        if (*v < lo || *v > hi) return "must be in " + d + " (got " + s + ")";
        return {};
      },
      desc.str());
}

std::string join(const std::vector<std::string>& values, const std::string& sep) {
  std::string t;
  for (const auto& v : values) t += (t.empty() ? "" : sep) + v;
  return t;
}

CLI::Validator one_of(const std::vector<std::string>& values) {
  return CLI::Validator(
      [values](std::string& s) -> std::string {
        for (const auto& v : values)
          if (s == v) return {};
        return "'" + s + "' is not one of " + join(values);
      },
      "{" + join(values, ",") + "}");
}

std::string exit_code_table(const std::vector<int>& codes) {
  std::string t = "Exit codes (docs/exit-codes.md):\n";
  for (int c : codes) {
    std::string n = std::to_string(c);
    // "  3 configuration invalid": codes right-aligned, one space (scripts grep "<code> <name>").
    t += "  " + std::string(n.size() < 3 ? 3 - n.size() : 0, ' ') + n + " " + exit_code::name(c) + "\n";
  }
  return t;
}

void set_exit_codes(CLI::App& app, const std::vector<int>& codes) {
  const std::string before = app.get_footer();
  app.footer((before.empty() ? "" : before + "\n") + exit_code_table(codes));
}

std::optional<int> parse(CLI::App& app, int argc, const char* const* argv) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e) == 0 ? exit_code::kOk : exit_code::kUsage;
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e) == 0 ? exit_code::kOk : exit_code::kUsage;
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e) == 0 ? exit_code::kOk : exit_code::kUsage;
  } catch (const CLI::ParseError& e) {
    // One line naming the option (CLI11 puts it first: "--noise: ...").
    std::cerr << app.get_name() << ": " << e.what() << " (see --help)\n";
    return exit_code::kUsage;
  }
  return std::nullopt;
}

namespace {
fs::path executable_path() {
  std::error_code ec;
  auto p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path{} : p;
}
bool under(const fs::path& p, const fs::path& dir) {
  if (p.empty() || dir.empty()) return false;
  const auto rel = p.lexically_relative(dir);
  return !rel.empty() && *rel.begin() != "..";
}
}  // namespace

std::vector<fs::path> config_search_path() {
  std::vector<fs::path> dirs;
  if (const char* d = std::getenv("MANIP_CONFIG_DIR"); d && *d) dirs.emplace_back(d);
  if (const char* x = std::getenv("XDG_CONFIG_HOME"); x && *x) {
    dirs.push_back(fs::path(x) / "manip");
  } else if (const char* h = std::getenv("HOME"); h && *h) {
    dirs.push_back(fs::path(h) / ".config" / "manip");
  }
  const auto exe = executable_path();
  const bool build_tree = under(exe, fs::path(MANIP_BUILD_TREE));
  if (!exe.empty() && !build_tree && exe.parent_path().filename() == "bin")
    dirs.push_back(exe.parent_path().parent_path() / "share" / "manip" / "config");
  if (*MANIP_INSTALL_CONFIG_DIR) {
    const fs::path baked(MANIP_INSTALL_CONFIG_DIR);
    if (dirs.empty() || dirs.back() != baked) dirs.push_back(baked);
  }
  if (build_tree && *MANIP_SOURCE_CONFIG_DIR) dirs.emplace_back(MANIP_SOURCE_CONFIG_DIR);
  return dirs;
}

std::string find_config(const std::string& given, const std::string& default_name) {
  const std::string name = given.empty() ? default_name : given;
  const fs::path p(name);
  std::error_code ec;
  // A path with a directory part, or a file in the working directory, is taken as given.
  if (p.has_parent_path() || fs::exists(p, ec)) {
    if (!fs::exists(p, ec)) throw ConfigError(name + ": configuration file not found");
    return name;
  }
  std::string searched;
  for (const auto& d : config_search_path()) {
    const auto f = d / p;
    if (fs::is_regular_file(f, ec)) return f.string();
    searched += (searched.empty() ? "" : ", ") + d.string();
  }
  throw ConfigError(name + ": configuration file not found (searched: ./" + (searched.empty() ? "" : ", " + searched) +
                    "; set MANIP_CONFIG_DIR or give --config PATH)");
}

}  // namespace manip::cli
