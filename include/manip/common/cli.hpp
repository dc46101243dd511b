#pragma once
// The command-line pieces every manip program shares (docs/cli.md is the
// contract): the same flag names for the same things in every app, the one
// exit-code table in each --help, option values checked before anything runs,
// and --config found from any working directory. CLI11 is the parser; an app
// builds its own CLI::App and adds these pieces to it:
//
//   CLI::App app{"..."};
//   manip::cli::Common c;
//   manip::cli::add_version(app, "manip_sim");
//   manip::cli::add_quiet(app, c.quiet);
//   manip::cli::add_out(app, c.out, "output LCM log");
//   manip::cli::add_force(app, c.force);
//   manip::cli::set_exit_codes(app, {ec::kOk, ec::kUsage, ec::kOutput, ec::kInternal});
//   if (const auto rc = manip::cli::parse(app, argc, argv)) return *rc;
//   const auto cfg = manip::cli::find_config(c.config, "rt.yaml");  // ConfigError (3) if nowhere
#include <CLI/CLI.hpp>

#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"

#include <filesystem>
#include <initializer_list>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

namespace manip::cli {

// The values behind the shared flags (an app adds only the ones it has).
struct Common {
  bool quiet = false;      // -q/--quiet: only warnings and errors on stderr
  bool force = false;      // --force: replace an existing output
  std::string out;         // --out FILE: the main output
  std::string config;      // --config FILE: as given (find_config resolves it)
  int movements = 0;       // --movements N: session length
};

// --version prints "<app> <version>" (manip/version.hpp) and exits 0.
void add_version(CLI::App& app, const std::string& app_name);
// -q/--quiet.
CLI::Option* add_quiet(CLI::App& app, bool& quiet);
// --out FILE (also -o). `what` says what the file is ("output LCM log").
CLI::Option* add_out(CLI::App& app, std::string& out, const std::string& what);
// --force: replace an existing output (without it, an existing file is never touched: exit 6).
CLI::Option* add_force(CLI::App& app, bool& force);
// --movements N, N in [min_n, max_n].
CLI::Option* add_movements(CLI::App& app, int& n, int min_n, int max_n, const std::string& what);
// --pulse-duration S, --pulse-amplitude N: the perturbation pulse of a
// simulated session (defaults: the paper's 0.15 s, 15 N, §3.2), in the
// ranges manip_rt's rt.yaml accepts (duration (0, 2] s; amplitude up to the
// default safety.max_pert_amplitude_n, 30 N).
void add_pulse(CLI::App& app, double& duration_s, double& amplitude_n);
// --config FILE; the help names the default file and the search path.
CLI::Option* add_config(CLI::App& app, std::string& config, const std::string& default_name, const std::string& what);

// A deprecated spelling of an option (docs/cli.md, "Deprecated aliases"):
// it keeps working, sets the same `target`, and prints one line on stderr
// ("manip_rt: --log is deprecated; use --out") whenever it is used, even with
// --quiet (it is a warning). Given together with `new_name` it is refused
// (exit 2). Add the replacement's checks to the returned option.
template <class T>
CLI::Option* add_deprecated_alias(CLI::App& app, const std::string& old_name, const std::string& new_name, T& target) {
  auto* o = app.add_option_function<T>(
      old_name,
      [&target, old_name, new_name, prog = app.get_name()](const T& v) {
        std::cerr << (prog.empty() ? std::string() : prog + ": ") << old_name << " is deprecated; use " << new_name
                  << "\n";
        target = v;
      },
      "deprecated alias of " + new_name);
  if (auto* n = app.get_option_no_throw(new_name)) o->excludes(n);
  return o;
}

// Validators (CLI11 prefixes the message with the option name: "--mass-kg: ...").
// A floating-point value that is finite (no nan, inf).
CLI::Validator finite();
// A finite value in [lo, hi].
CLI::Validator finite_range(double lo, double hi);
// One of `values`; the help and the error list them (so --help lists exactly what is accepted).
CLI::Validator one_of(const std::vector<std::string>& values);
// "a | b | c" for help texts.
std::string join(const std::vector<std::string>& values, const std::string& sep = " | ");

// The rows of the one exit-code table (common/exit_codes.hpp) for `codes`, in
// the order given:
//   Exit codes (docs/exit-codes.md):
//       0 ok
//       2 usage error
std::string exit_code_table(const std::vector<int>& codes);
// Appends exit_code_table(codes) to the app's footer (after any footer set before).
void set_exit_codes(CLI::App& app, const std::vector<int>& codes);

// Parses; returns an exit code when the program must stop now: 0 after --help
// or --version (printed to stdout), 2 (usage) after a bad command line (one
// line on stderr naming the option, prefixed by the app name). nullopt: go on.
std::optional<int> parse(CLI::App& app, int argc, const char* const* argv);

// The directories searched for a configuration file named without a directory,
// first match wins (docs/cli.md):
//   1. $MANIP_CONFIG_DIR
//   2. $XDG_CONFIG_HOME/manip (~/.config/manip when XDG_CONFIG_HOME is unset)
//   3. <prefix>/share/manip/config, prefix = the directory above the running
//      executable's bin/ (so an extracted or relocated package finds its own)
//   4. the install prefix baked in at configure time (CMAKE_INSTALL_PREFIX)
//   5. the source tree's config/, only when the executable runs from the build tree
std::vector<std::filesystem::path> config_search_path();
// Resolves --config. `given` empty: searches for `default_name`. `given` with a
// directory part (or an existing file relative to the working directory): used
// as is. Otherwise `given` is searched like a default name. Throws ConfigError
// (exit 3) naming the file and every place searched when nothing is found.
std::string find_config(const std::string& given, const std::string& default_name);

// The one main() of every app: a typed set-up error (common/errors.hpp) is
// one line "<program>: <reason>" with its documented exit code; any other
// exception is a bug (exit 70, "internal error").
template <class Run>
int run_main(const char* program, Run&& run, int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const Error& e) {
    std::cerr << program << ": " << e.what() << "\n";
    return e.exit_code();
  } catch (const std::exception& e) {
    std::cerr << program << ": internal error: " << e.what() << "\n";
    return exit_code::kInternal;
  }
}

}  // namespace manip::cli
