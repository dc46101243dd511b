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
#include "manip/diagnosis/manipulandum.hpp"
#include "manip/diagnosis/report.hpp"
#include "manip/diagnosis/single_joint.hpp"

namespace {

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
  app.add_option("logs", logs, "manipulandum session logs (.lcm) of manip_rt or manip_sim; several logs are pooled only if their configurations agree");
  bool no_pem = false;
  int poly_order = 1;
  bool time_varying = false;
  app.add_flag("--time-varying", time_varying, "manipulandum: add the time-varying-stiffness mechanism to the library (off by default: confounded with inertia terms in a 150 ms window)");
  app.add_option("--poly-order", poly_order, "manipulandum: per-trial nuisance polynomial projected out (-1 none; default 1)")->check(CLI::Range(-1, 8));
  double t_est = 0.15;
  app.add_flag("--no-default-method", no_pem, "manipulandum: do not fit the estimator's default method (pem) for comparison");
  app.add_option("--t-est", t_est, "manipulandum: estimation window after onset (s), as estimate_impedance")->check(CLI::Range(0.05, 1.0));
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
    std::cerr << "diagnose_model: give LOG.lcm [LOG...] or --single-joint FILE.csv; see --help\n";
    return exit_code::kUsage;
  }
  if (!logs.empty() && !single_joint.empty()) {
    std::cerr << "diagnose_model: give either session logs or --single-joint FILE.csv, not both\n";
    return exit_code::kUsage;
  }
  if (!quiet) eo.progress = [](const std::string& s) { std::cerr << "diagnose_model: " << s << "\n"; };
  if (!json_out.empty()) {  // fail before the work if the output cannot be written
    std::ofstream probe(json_out, std::ios::app);
    if (!probe) throw OutputError(json_out + ": cannot be written");
  }
  if (!logs.empty()) {
    std::vector<diagnosis::CollectedSession> sessions;
    for (const auto& l : logs) {
      if (eo.progress) eo.progress("reading " + l);
      sessions.push_back(diagnosis::collect_log(l));
    }
    diagnosis::PlanarOptions po;
    po.estimator.pipeline.t_est_s = t_est;
    po.pem_baseline = !no_pem;
    po.nuisance_order = poly_order;
    if (eo.progress) eo.progress("isolating the variational signals (eq. 21)" + std::string(no_pem ? "" : " and fitting the default method"));
    auto prep = diagnosis::prepare_planar(sessions, po, eo.folds);
    const auto lib = diagnosis::planar_library(po.nuisance_order, time_varying);
    eo.require_plausible = true;
    eo.rank_by_t = true;
    const auto res = diagnosis::diagnose(prep.data, lib, eo);
    if (res.misfit_found() && po.pem_baseline) {
      if (eo.progress) eo.progress("refitting the default method with the extension");
      const auto corr = diagnosis::extension_correction(prep.data, res, lib);
      prep.pem_extended = diagnosis::fit_default_method(prep, &corr);
      prep.refined = diagnosis::refine_with_default_method(prep, res, lib, eo.progress);
    }
    diagnosis::ReportContext ctx;
    ctx.front_end = "manipulandum session, variational signals of eq. 21";
    char buf[400];
    std::snprintf(buf, sizeof buf,
                  "%zu perturbed trials, window [0, %.3g] s after onset; estimator pipeline (SG jerk window %d, high-pass %.3g Hz); "
                  "two equations (x1, x2) per sample; truth channels not read",
                  prep.data.planar.size(), prep.t_est_s, prep.sg_window, po.estimator.pipeline.hp_cutoff_hz);
    ctx.preprocessing = buf;
    ctx.baseline_equation = "Δu_ext - M_BSP Δẍ = D Δẋ + K Δx (eq. 14 with eq. 21's Δu_ext; D full, K symmetric, M_BSP eq. 16 fixed)";
    ctx.cv_units = "trials (both axes of a trial in the same fold; bootstrap resamples trials)";
    ctx.target_word = "target";
    const auto pr = diagnosis::planar_report(prep, res, lib);
    ctx.extra_text = pr.text;
    std::cout << diagnosis::text_report(res, ctx);
    if (!json_out.empty()) {
      auto j = diagnosis::json_report(res, ctx);
      j["manipulandum"] = pr.json;
      std::ofstream out(json_out);
      out << j.dump(2) << "\n";
      if (!out) throw OutputError(json_out + ": write failed");
    }
    return exit_code::kOk;
  }
  sj.torque_sign = sign == "auto" ? 0 : (sign == "-1" ? -1 : 1);
  if (inertia >= 0) {
    sj.inertia_fixed = true;
    sj.fixed_inertia_kgm2 = inertia;
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
