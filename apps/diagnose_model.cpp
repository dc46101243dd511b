// diagnose_model: what a model gets wrong on measured data, the likely cause,
// the extended model and its measured gain (docs/diagnosis.md).
// Thin main: options, the single-joint front end, the engine, the reports.
#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <string>

#include <CLI/CLI.hpp>

#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/diagnosis/engine.hpp"
#include "manip/diagnosis/report.hpp"
#include "manip/diagnosis/single_joint.hpp"

namespace {

bool ends_with(const std::string& s, const std::string& e) {
  return s.size() >= e.size() && s.compare(s.size() - e.size(), e.size(), e) == 0;
}

int run(int argc, char** argv) {
  using namespace manip;
  CLI::App app{"diagnose_model: show what the model gets wrong on measured data, name the cause, extend the model and measure the gain"};
  std::string single_joint, json_out;
  std::vector<std::string> logs;
  bool quiet = false;
  diagnosis::SingleJointOptions sj;
  diagnosis::EngineOptions eo;
  std::string sign = "auto";
  double inertia = -1.0;
  app.add_option("--single-joint", single_joint, "single-joint position-perturbation record (CSV: docs/diagnosis.md)");
  app.add_option("logs", logs, "manipulandum session logs (.lcm): not supported yet");
  app.add_option("--json", json_out, "write the report as JSON to this file");
  app.add_flag("-q,--quiet", quiet, "no progress on stderr");
  app.add_option("--torque-sign", sign, "auto (K > 0 decides), +1 or -1")->check(CLI::IsMember({"auto", "+1", "-1", "1"}));
  app.add_option("--inertia", inertia, "fix the inertia to this value (kg m^2); enables the wrong-inertia mechanism")->check(CLI::NonNegativeNumber);
  app.add_option("--cutoff", sj.cutoff_hz, "Savitzky-Golay -3 dB cut-off (Hz)")->check(CLI::PositiveNumber);
  app.add_option("--folds", eo.folds, "cross-validation folds")->check(CLI::Range(3, 100));
  app.add_option("--bootstrap", eo.bootstrap, "block-bootstrap replicates")->check(CLI::Range(20, 100000));
  app.add_option("--alpha", eo.alpha, "family-wise significance level per greedy round")->check(CLI::Range(1e-6, 0.5));
  app.footer(
      "Exit codes: 0 diagnosis done; 2 bad command line; 4 input unusable (file:line: reason);\n"
      "            6 output cannot be written; 70 internal error.");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? exit_code::kOk : exit_code::kUsage;
  }
  if (single_joint.empty() && logs.empty()) {
    std::cerr << "diagnose_model: give --single-joint FILE.csv (manipulandum logs are not supported yet); see --help\n";
    return exit_code::kUsage;
  }
  if (!logs.empty()) {
    for (const auto& l : logs)
      if (ends_with(l, ".lcm") || !single_joint.empty())
        throw InputError(l + ": manipulandum session logs are not supported yet: the engine is ready, the front end that "
                             "turns a session's perturbed trials into segments (Δu target, Δx/Δẋ/Δẍ and M_BSP regressors) is missing "
                             "(issue 11); use --single-joint FILE.csv for single-joint records");
    throw UsageError(logs.front() + ": unknown input; use --single-joint FILE.csv");
  }
  sj.torque_sign = sign == "auto" ? 0 : (sign == "-1" ? -1 : 1);
  if (inertia >= 0) {
    sj.inertia_fixed = true;
    sj.fixed_inertia_kgm2 = inertia;
  }
  if (!quiet) eo.progress = [](const std::string& s) { std::cerr << "diagnose_model: " << s << "\n"; };
  if (!json_out.empty()) {  // fail before the work if the output cannot be written
    std::ofstream probe(json_out, std::ios::app);
    if (!probe) throw OutputError(json_out + ": cannot be written");
  }
  const auto rec = diagnosis::read_single_joint_csv(single_joint);
  const auto prep = diagnosis::prepare_single_joint(rec, sj);
  const auto lib = diagnosis::standard_library();
  const auto res = diagnosis::diagnose(prep.data, lib, eo);
  diagnosis::ReportContext ctx;
  ctx.front_end = "single-joint CSV, position in, torque out";
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "%zu samples at %.6g s; Savitzky-Golay order %d, window %d (-3 dB at %.1f Hz) on position and torque; torque sign %+d%s",
                rec.pos_rad.size(), rec.dt_s, sj.polyorder, prep.window, prep.cutoff_hz, prep.torque_sign,
                prep.sign_flipped_automatically ? " (flipped: the record stores the reaction torque, baseline K was negative)" : "");
  ctx.preprocessing = buf;
  std::cout << diagnosis::text_report(res, ctx);
  if (!json_out.empty()) {
    std::ofstream out(json_out);
    out << diagnosis::json_report(res, ctx).dump(2) << "\n";
    if (!out) throw OutputError(json_out + ": write failed");
  }
  return exit_code::kOk;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const manip::Error& e) {
    std::cerr << "diagnose_model: " << e.what() << "\n";
    return e.exit_code();
  } catch (const std::exception& e) {
    std::cerr << "diagnose_model: internal error: " << e.what() << "\n";
    return manip::exit_code::kInternal;
  }
}
