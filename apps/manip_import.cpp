// manip_import: a session recorded with another rig (MATLAB/Simulink MAT v5 or
// v7.3, or CSV) converted into a manip log through a YAML mapping, so that
// estimate_impedance reads it like any other (docs/import.md). Command line:
// common/cli.hpp (docs/cli.md): --version, -q, -o/--out, --force, the exit-code
// table in --help.
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "manip/common/cli.hpp"
#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/importer/convert.hpp"
#include "manip/importer/mapping.hpp"
#include "manip/version.hpp"

namespace {

namespace ec = manip::exit_code;
namespace cli = manip::cli;

const std::vector<int> kExitCodes = {ec::kOk, ec::kUsage, ec::kConfig, ec::kInput, ec::kOutput, ec::kInternal};
const char* kExitNotes =
    "What the codes mean for manip_import (several: the most severe wins, docs/exit-codes.md):\n"
    "    0: log written (warnings about trials estimate_impedance will exclude are still printed with -q)\n"
    "    2: bad command line: nothing read\n"
    "    3: the mapping is invalid or does not fit the data (mapping.yaml:line: key: reason)\n"
    "    4: the recording cannot be read or is unusable (e.g. time not increasing)\n"
    "    6: the output exists (no --force; checked before the recording is read) or cannot be written;\n"
    "       nothing is left behind\n";

int run(int argc, char** argv) {
  CLI::App app{"manip_import " + std::string(manip::kVersion) +
                   ": convert a recording of another rig (MAT v5/v7.3 or CSV) into a manip session log through a "
                   "YAML mapping (docs/import.md, config/import-example.yaml).",
               "manip_import"};
  app.footer(kExitNotes);
  std::string mapping, input;
  cli::Common c;
  cli::add_version(app, "manip_import");
  cli::add_quiet(app, c.quiet);
  app.add_option("mapping", mapping, "YAML mapping (what is what in the recording)")->required();
  app.add_option("input", input, "the recording: .mat (v5 or v7.3) or .csv with a header line")->required();
  cli::add_out(app, c.out, "the manip LCM log to write")->required();
  cli::add_force(app, c.force);
  cli::set_exit_codes(app, kExitCodes);
  if (const auto rc = cli::parse(app, argc, argv)) return *rc;

  // Most severe first (docs/exit-codes.md: config > output > input): the
  // mapping is checked, then the output is refused before a recording (MAT
  // files run to gigabytes) is read. import_session checks both again.
  (void)manip::importer::load_mapping(mapping);
  std::error_code e;
  if (!c.force && std::filesystem::exists(c.out, e))
    throw manip::OutputError(c.out + ": exists (pass --force to overwrite it); nothing was read");

  const auto s = manip::importer::import_session(mapping, input, c.out, c.force);
  if (!c.quiet)
    std::cerr << "manip_import: wrote " << c.out << " from " << input << " (" << s.input_format << "): " << s.samples
              << " samples at " << s.sample_rate_hz << " Hz (" << s.duration_s << " s), " << s.trials << " trials, "
              << s.perturbed << " perturbed\n"
              << "manip_import: hand at trial start / end, mean, shoulder frame: (" << s.mean_start_shoulder_m(0)
              << ", " << s.mean_start_shoulder_m(1) << ") m / (" << s.mean_end_shoulder_m(0) << ", "
              << s.mean_end_shoulder_m(1) << ") m (a reach runs along +x2; if not, check `frame`)\n";
  // Trials the estimator will exclude or whose onset was moved: warnings, printed also with -q.
  for (const auto& note : s.notes) std::cerr << "manip_import: warning: " << note << "\n";
  return ec::kOk;
}

}  // namespace

int main(int argc, char** argv) { return manip::cli::run_main("manip_import", run, argc, argv); }
