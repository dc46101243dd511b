// manip_import: a session recorded with another rig (MATLAB/Simulink MAT v5 or
// v7.3, or CSV) converted into a manip log through a YAML mapping, so that
// estimate_impedance reads it like any other (docs/import.md).
#include <CLI/CLI.hpp>

#include <iostream>

#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/importer/convert.hpp"
#include "manip/version.hpp"

int main(int argc, char** argv) {
  namespace ec = manip::exit_code;
  CLI::App app{"manip_import " + std::string(manip::kVersion) +
               ": convert a recording of another rig (MAT v5/v7.3 or CSV) into a manip session log through a YAML "
               "mapping (docs/import.md, config/import-example.yaml)."};
  auto row = [](int code, const std::string& what) {
    return "\n  " + std::to_string(code) + "  " + ec::name(code) + (what.empty() ? "" : ": " + what);
  };
  app.footer("Exit codes:" + row(ec::kOk, "log written") + row(ec::kUsage, "bad command line") +
             row(ec::kConfig, "the mapping is invalid or does not fit the data (file:line: key: reason)") +
             row(ec::kInput, "the recording cannot be read or is unusable (e.g. time not increasing)") +
             row(ec::kOutput, "the output exists (no --force) or cannot be written; nothing is left behind") +
             row(ec::kInternal, "a bug: please report it"));
  std::string mapping, input, out;
  bool force = false;
  app.add_option("mapping", mapping, "YAML mapping (what is what in the recording)")->required();
  app.add_option("input", input, "the recording: .mat (v5 or v7.3) or .csv with a header line")->required();
  app.add_option("-o,--out", out, "the manip LCM log to write")->required();
  app.add_flag("--force", force, "overwrite an existing output");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? ec::kOk : ec::kUsage;
  }
  try {
    const auto s = manip::importer::import_session(mapping, input, out, force);
    std::cerr << "manip_import: wrote " << out << " from " << input << " (" << s.input_format << "): " << s.samples
              << " samples at " << s.sample_rate_hz << " Hz (" << s.duration_s << " s), " << s.trials << " trials, "
              << s.perturbed << " perturbed\n"
              << "manip_import: hand at trial start / end, mean, shoulder frame: (" << s.mean_start_shoulder_m(0) << ", "
              << s.mean_start_shoulder_m(1) << ") m / (" << s.mean_end_shoulder_m(0) << ", " << s.mean_end_shoulder_m(1)
              << ") m (a reach runs along +x2; if not, check `frame`)\n";
    for (const auto& note : s.notes) std::cerr << "manip_import: note: " << note << "\n";
    return ec::kOk;
  } catch (const manip::Error& e) {
    std::cerr << "manip_import: " << e.what() << "\n";
    return e.exit_code();
  } catch (const std::exception& e) {
    std::cerr << "manip_import: internal error: " << e.what() << "\n";
    return ec::kInternal;
  }
}
