// diagnose_model: what a model gets wrong on measured data, the likely cause,
// the extended model and its measured gain (docs/diagnosis.md).
// Thin main: options, the single-joint front end, the engine, the reports.
// Command line: common/cli.hpp (docs/cli.md): --version, -q, --force, the
// exit-code table in --help.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "manip/common/cli.hpp"
#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/common/output_file.hpp"
#include "manip/common/temp_dir.hpp"
#include "manip/diagnosis/engine.hpp"
#include "manip/diagnosis/likelihood_stage.hpp"
#include "manip/diagnosis/manipulandum.hpp"
#include "manip/diagnosis/report.hpp"
#include "manip/diagnosis/single_joint.hpp"
#include "manip/diagnosis/torque_lag.hpp"
#include "manip/estimation/report/render.hpp"
#include "manip/version.hpp"

namespace {

namespace ec = manip::exit_code;
const std::vector<int> kExitCodes = {ec::kOk, ec::kUsage, ec::kInput, ec::kOutput, ec::kInternal};
const char* kExitNotes =
    "What the codes mean for diagnose_model (several: the most severe wins, docs/exit-codes.md):\n"
    "    0: diagnosis done, with or without a misfit found\n"
    "    2: bad command line (also: no input, logs and --single-joint together, an id of --mechanisms not in\n"
    "       the library)\n"
    "    4: an input is unusable: missing or unreadable, a malformed line (FILE:LINE: reason), too short for\n"
    "       the cross-validation or too few perturbed trials, logs with different configurations\n"
    "    6: the --json file exists or the --plots DIR is not empty (no --force; checked before any input is\n"
    "       read), an output cannot be written, or Python/matplotlib is missing for --plots; nothing is left\n"
    "       behind (the text report is printed and --json written before the figures are drawn)\n";

namespace fs = std::filesystem;

// --plots DIR: refused before any input is read when it exists and is not
// empty (unless --force) or is not a directory (as estimate_impedance).
void check_plots_dir(const std::string& dir, bool force) {
  std::error_code e;
  if (fs::exists(dir, e) && !fs::is_directory(dir, e)) throw manip::OutputError("--plots " + dir + ": exists and is not a directory");
  if (!force && fs::is_directory(dir, e) && !fs::is_empty(dir, e))
    throw manip::OutputError("--plots " + dir + ": exists and is not empty (pass --force to overwrite its files); nothing was read");
}

// The figures: the report JSON (with traces) into a temporary directory, then
// python -m manipplot.diagnosis through the estimator's render mechanism
// (files moved into DIR only when all were drawn; an existing file is
// replaced only with --force).
void draw_plots(const nlohmann::json& j, const std::string& dir, bool force) {
  const manip::ScopedTempDir tmp_dir("diagnose_model");
  const fs::path& tmp = tmp_dir.path();
  const std::string results = (tmp / "diagnosis.json").string();
  manip::write_file_atomically(results, j.dump(1) + "\n", true);
  const auto r = manip::estimation::render_module_into("manipplot.diagnosis", {results}, "png,pdf", dir, force);
  for (const auto& n : r.notes) std::cerr << "diagnose_model: " << n << "\n";
  if (r.manipplot_exit != 0) throw manip::OutputError("--plots " + dir + ": some figures were not drawn (see above)");
}

int run(int argc, char** argv) {
  using namespace manip;
  namespace cli = manip::cli;
  CLI::App app{"diagnose_model " + std::string(manip::kVersion) +
                   ": show what the model gets wrong on measured data, name the cause, extend the model and measure "
                   "the gain (docs/diagnosis.md)",
               "diagnose_model"};
  app.footer(kExitNotes);
  std::string single_joint, json_out, plots_dir;
  std::vector<std::string> logs;
  cli::Common c;
  cli::add_version(app, "diagnose_model");
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
  bool directional = false;
  app.add_flag("--directional-reflex", directional,
               "manipulandum: add the direction-dependent reflex (one muscle group, acting only when stretched) to the library (off by "
               "default: it also fits a residual common to all trials along the reach)");
  std::vector<std::string> mechanisms;
  app.add_option("--mechanisms", mechanisms,
                 "manipulandum: test only these mechanisms of the library (comma-separated ids, e.g. "
                 "actuation_delay,stage_friction; docs/diagnosis.md): a confirmatory test, the family-wise level is over them")
      ->delimiter(',');
  app.add_option("--poly-order", poly_order, "manipulandum: per-trial nuisance polynomial projected out (-1 none; default 1)")->check(CLI::Range(-1, 8));
  double t_est = 0.15;
  app.add_flag("--no-default-method", no_pem, "manipulandum: do not fit the estimator's default method (pem) for comparison");
  app.add_option("--t-est", t_est, "manipulandum: estimation window after onset (s), as estimate_impedance")->check(CLI::Range(0.05, 1.0));
  std::string position_source = "auto";
  app.add_option("--position-source", position_source,
                 "manipulandum: the handle position: auto (default: the encoder, moving to the admittance's x_ref when the "
                 "stages' tracking is most of eq. 21's disagreement with the force sensor, the report's \"tracking\" line) | "
                 "encoder (stays) | reference (x_ref aligned, from the start)")
      ->check(CLI::IsMember({"auto", "encoder", "reference"}));
  app.add_option("--json", json_out, "write the report as JSON to this file (an existing file is kept unless --force)");
  app.add_option("--plots", plots_dir,
                 "draw the figures (PNG + PDF; python -m manipplot.diagnosis, docs/diagnosis.md) into DIR, with diagnosis.json "
                 "(a non-empty DIR is refused unless --force)");
  cli::add_force(app, c.force);
  cli::add_quiet(app, c.quiet)->description("no progress on stderr (only warnings and errors)");
  app.add_option("--torque-sign", sign, "auto (K > 0 decides), +1 or -1")->check(CLI::IsMember({"auto", "+1", "-1", "1"}));
  app.add_option("--inertia", inertia, "fix the inertia to this value (kg m^2); enables the wrong-inertia mechanism")->check(CLI::NonNegativeNumber);
  app.add_option("--cutoff", sj.cutoff_hz, "Savitzky-Golay -3 dB cut-off (Hz)")->check(CLI::PositiveNumber);
  app.add_option("--folds", eo.folds, "cross-validation folds")->check(CLI::Range(3, 100));
  app.add_option("--bootstrap", eo.bootstrap, "block-bootstrap replicates")->check(CLI::Range(20, 100000));
  app.add_option("--alpha", eo.alpha, "family-wise significance level per greedy round")->check(CLI::Range(1e-6, 0.5));
  cli::set_exit_codes(app, kExitCodes);
  if (const auto rc = cli::parse(app, argc, argv)) return *rc;
  if (single_joint.empty() && logs.empty()) {
    std::cerr << "diagnose_model: give LOG.lcm [LOG...] or --single-joint FILE.csv; see --help\n";
    return ec::kUsage;
  }
  if (!logs.empty() && !single_joint.empty()) {
    std::cerr << "diagnose_model: give either session logs or --single-joint FILE.csv, not both\n";
    return ec::kUsage;
  }
  if (!mechanisms.empty()) {
    if (logs.empty()) {
      std::cerr << "diagnose_model: --mechanisms applies to session logs, not to --single-joint\n";
      return ec::kUsage;
    }
    // Checked before any input is read, against the library the other flags make.
    std::vector<std::string> known;
    std::string list;
    for (const auto& m : diagnosis::planar_library(poly_order, time_varying, directional)) {
      known.push_back(m->id());
      list += (list.empty() ? "" : ", ") + m->id();
    }
    for (const auto& id : mechanisms)
      if (std::find(known.begin(), known.end(), id) == known.end()) {
        const char* needs = id == "directional_reflex" ? "; it needs --directional-reflex"
                            : id == "time_varying_stiffness" ? "; it needs --time-varying" : "";
        std::cerr << "diagnose_model: --mechanisms: '" << id << "' is not in the manipulandum library (" << list << ")" << needs << "\n";
        return ec::kUsage;
      }
  }
  if (!c.quiet) eo.progress = [](const std::string& s) { std::cerr << "diagnose_model: " << s << "\n"; };
  // Refused before any input is read (exists without --force, directory not
  // writable); written to a temporary beside it and renamed when complete, so
  // a failed run leaves neither a truncated file nor a temporary.
  std::optional<AtomicOutput> json_file;
  if (!json_out.empty()) json_file.emplace(json_out, c.force);
  if (!plots_dir.empty()) check_plots_dir(plots_dir, c.force);
  const bool want_json = json_file.has_value() || !plots_dir.empty();
  eo.keep_predictions = want_json;  // the JSON "traces" (figures)
  const auto write_json = [&](const nlohmann::json& j) {
    const std::string text = j.dump(2) + "\n";
    if (std::fputs(text.c_str(), json_file->stream()) < 0) throw OutputError(json_out + ": write failed");
    json_file->commit();
  };
  if (!logs.empty()) {
    std::vector<diagnosis::CollectedSession> sessions;
    for (const auto& l : logs) {
      if (eo.progress) eo.progress("reading " + l);
      sessions.push_back(diagnosis::collect_log(l));
    }
    diagnosis::PlanarOptions po;
    po.estimator.pipeline.t_est_s = t_est;
    po.estimator.position = *estimation::parse_position_source(position_source);  // checked by CLI11 above
    po.pem_baseline = !no_pem;
    po.nuisance_order = poly_order;
    po.directional_reflex = directional;
    po.mechanisms = mechanisms;
    const auto run = diagnosis::run_planar(sessions, po, eo, time_varying);
    const auto& prep = run.prep;
    const auto& res = run.dg;
    diagnosis::ReportContext ctx;
    ctx.front_end = "manipulandum session, variational signals of eq. 21";
    char buf[400];
    std::snprintf(buf, sizeof buf,
                  "%zu perturbed trials, window [0, %.3g] s after onset; estimator pipeline (SG jerk window %d, high-pass %.3g Hz); "
                  "two equations (x1, x2) per sample; truth channels not read",
                  prep.data.planar.size(), prep.t_est_s, prep.sg_window, po.estimator.pipeline.hp_cutoff_hz);
    ctx.preprocessing = buf;
    if (!mechanisms.empty()) {
      ctx.preprocessing += "; library restricted to ";
      for (std::size_t k = 0; k < mechanisms.size(); ++k) ctx.preprocessing += (k ? ", " : "") + mechanisms[k];
      ctx.preprocessing += " (--mechanisms)";
    }
    ctx.baseline_equation = "Δu_ext - M_BSP Δẍ = D Δẋ + K Δx (eq. 14 with eq. 21's Δu_ext; D full, K symmetric, M_BSP eq. 16 fixed)";
    ctx.cv_units = "trials (both axes of a trial in the same fold; bootstrap resamples trials)";
    ctx.target_word = "target";
    const auto pr = diagnosis::planar_report(prep, res, run.lib);
    ctx.extra_text = pr.text + diagnosis::likelihood_text(run.lk) + diagnosis::conclusion_text(run.concl, res);
    std::cout << diagnosis::text_report(res, ctx);
    if (want_json) {
      auto j = diagnosis::json_report(res, ctx);
      j["manipulandum"] = pr.json;
      j["likelihood"] = diagnosis::likelihood_json(run.lk);
      j["conclusion"] = diagnosis::conclusion_json(run.concl);
      j["traces"] = diagnosis::traces_json(prep.data, res);
      if (json_file) write_json(j);
      if (!plots_dir.empty()) draw_plots(j, plots_dir, c.force);
    }
    return ec::kOk;
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
  ctx.preprocessing = rec.columns_note.empty() ? std::string(buf) : rec.columns_note + "\n  " + buf;
  const auto lag = diagnosis::fit_torque_lag(prep.data, res, lib, eo);
  ctx.extra_text = diagnosis::torque_lag_text(lag);
  const auto checks = diagnosis::single_joint_physical_checks(res);
  if (!checks.empty()) {
    ctx.extra_text += "\nPhysical checks of the baseline:\n";
    for (const auto& pc : checks) ctx.extra_text += "  " + pc.text + "\n";
  }
  std::cout << diagnosis::text_report(res, ctx);
  if (want_json) {
    auto j = diagnosis::json_report(res, ctx);
    j["torque_lag"] = diagnosis::torque_lag_json(lag);
    j["physical_checks"] = nlohmann::json::array();
    for (const auto& pc : checks) {
      nlohmann::json e = {{"what", pc.what}, {"text", pc.text}};
      if (pc.least_lag_s > 0) e["least_torque_lag_s"] = pc.least_lag_s;
      j["physical_checks"].push_back(e);
    }
    j["traces"] = diagnosis::traces_json(prep.data, res);
    if (json_file) write_json(j);
    if (!plots_dir.empty()) draw_plots(j, plots_dir, c.force);
  }
  return ec::kOk;
}

}  // namespace

int main(int argc, char** argv) { return manip::cli::run_main("diagnose_model", run, argc, argv); }
