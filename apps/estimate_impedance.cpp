// estimate_impedance: involuntary impedance (D, K) of the arm from manip LCM
// logs (paper §3, Table 1). Thin main: options -> estimation library -> outputs.
#include <CLI/CLI.hpp>

#include <filesystem>
#include <fstream>
#include <iostream>

#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/estimation/report.hpp"
#include "manip/version.hpp"

namespace {

namespace ec = manip::exit_code;

std::string exit_code_help() {
  std::string t = "Exit codes (common/exit_codes.hpp, docs/estimator.md):\n";
  for (const auto& [code, what] : std::initializer_list<std::pair<int, const char*>>{
           {ec::kOk, "every log estimated, nothing excluded or flagged"},
           {ec::kPartial, "estimated, but trials were excluded or a fit is flagged not identifiable"},
           {ec::kUsage, "bad command line"},
           {ec::kConfig, "settings file (--config) invalid or unreadable"},
           {ec::kInput, "a log unusable (missing, not LCM, no/invalid session message, unknown schema); other logs still processed"},
           {ec::kNothing, "no usable perturbed trial in any readable log"},
           {ec::kOutput, "an output (--json, --csv, --plots, --export-signals) cannot be written"},
           {ec::kInternal, "internal error (a bug: please report it)"}})
    t += "  " + std::to_string(code) + "  " + what + "\n";
  return t;
}

std::string method_help() {
  std::string t = "Methods (--method; 'all' runs every one):\n";
  for (const auto* m : manip::estimation::registered_methods()) t += "  " + m->name() + ": " + m->description() + "\n";
  return t;
}

int run(int argc, char** argv) {
  using namespace manip::estimation;
  CLI::App app{"estimate_impedance " + std::string(manip::kVersion) +
               ": involuntary impedance (damping D, stiffness K) from manip session logs."};
  app.footer(method_help() + exit_code_help());
  std::vector<std::string> logs;
  std::string method = default_method(), cutoff = "1", config, json_path, csv_path, signals_dir, plots_dir;
  double t_est = -1, cutoff_thr = -1, oe_pre = -1;
  int sg_window = -1, oe_poly = -1;
  std::string k_model, force_source;
  bool estimate_m = false, no_jackknife = false, quiet = false;
  app.add_option("logs", logs, "LCM log files (one session each)")->required();
  app.add_option("--method", method, method_list() + " | all (default " + default_method() + ", listed below)");
  app.add_option("--cutoff", cutoff, "high-pass cut-off in Hz, or 'auto' from the jerk PSDs (default 1, paper §4.3)");
  app.add_option("--cutoff-threshold-db", cutoff_thr, "perturbed/unperturbed PSD ratio for --cutoff auto (default 3 dB)");
  app.add_option("--t-est", t_est, "estimation window after onset [s] (default 0.15)");
  app.add_option("--sg-window", sg_window, "Savitzky-Golay window in samples (default: -3 dB at 30 Hz, 225 at 4 kHz)");
  app.add_option("--k-model", k_model, "symmetric (eq. 30) | full (8 parameters) for paper methods");
  app.add_flag("--estimate-m", estimate_m, "estimate M too (eq. 24-29) in paper methods instead of M_BSP");
  app.add_option("--force-source", force_source, "admittance (eq. 21) | sensor: Δu_ext for paper methods");
  app.add_option("--oe-pre", oe_pre, "output error: data before onset [s] (default 0.05)");
  app.add_option("--oe-poly-order", oe_poly, "output error: per-trial polynomial order (default 3)");
  app.add_flag("--no-jackknife", no_jackknife, "output error: least-squares SE instead of the jackknife over trials");
  app.add_option("--config", config, "estimator settings YAML (config/estimator.yaml); flags override it");
  app.add_option("--json", json_path, "write results as JSON (layout: docs/estimator.md)");
  app.add_option("--csv", csv_path, "write per-trial and summary rows as CSV");
  app.add_option("--export-signals", signals_dir, "write per-trial Δ signals as CSV into DIR");
  app.add_option("--plots", plots_dir, "write SVG plots (PSDs, variational dynamics, D and K per angle) into DIR");
  app.add_flag("-q,--quiet", quiet, "no progress on stderr");
  app.set_version_flag("--version", std::string(manip::kVersion));
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? ec::kOk : ec::kUsage;
  }

  EstimatorSettings s;
  if (!config.empty()) s = load_estimator_settings(config, s);  // ConfigError: exit 3
  try {
    if (method == "all") s.methods = all_methods();
    else if (!app.get_option("--method")->empty() || config.empty()) s.methods = {method};
    if (!app.get_option("--cutoff")->empty() || config.empty()) {
      if (cutoff == "auto") s.cutoff_auto = true;
      else {
        s.cutoff_auto = false;
        s.pipeline.hp_cutoff_hz = std::stod(cutoff);
        if (!(s.pipeline.hp_cutoff_hz > 0)) throw std::invalid_argument("--cutoff must be positive or 'auto'");
      }
    }
    if (cutoff_thr > 0) s.cutoff_auto_threshold_db = cutoff_thr;
    if (t_est > 0) s.pipeline.t_est_s = s.oe.t_est_s = s.pem.t_est_s = t_est;
    if (sg_window > 0) {
      if (sg_window % 2 == 0) throw std::invalid_argument("--sg-window must be odd");
      s.pipeline.sg_window = sg_window;
    }
    if (!k_model.empty()) {
      if (k_model == "symmetric") s.ls.k_model = StiffnessModel::symmetric;
      else if (k_model == "full") s.ls.k_model = StiffnessModel::full;
      else throw std::invalid_argument("--k-model must be symmetric or full");
    }
    if (estimate_m) s.ls.estimate_m = true;
    if (!force_source.empty()) {
      if (force_source == "admittance") s.ls.force = ForceSource::admittance;
      else if (force_source == "sensor") s.ls.force = ForceSource::sensor;
      else throw std::invalid_argument("--force-source must be admittance or sensor");
    }
    if (oe_pre >= 0) s.oe.t_pre_s = oe_pre;
    if (oe_poly >= 0) s.oe.poly_order = oe_poly;
    if (no_jackknife) s.oe.jackknife = false;
    s.keep_windows = !signals_dir.empty() || !plots_dir.empty();
    SessionEstimator probe(s);  // validates method names
  } catch (const std::logic_error& e) {  // std::stod and the checks above: a bad option value
    throw manip::UsageError(e.what());
  }

  int rc = ec::kOk;
  int n_readable = 0;
  bool any_estimate = false;
  std::vector<std::pair<std::string, Report>> reports;
  nlohmann::json all = {{"manip_version", manip::kVersion}, {"settings", settings_to_json(s)}, {"sessions", nlohmann::json::array()}};
  for (const auto& log : logs) {
    if (!quiet) std::cerr << "estimate_impedance: reading " << log << " ...\n";
    Report r;
    try {
      r = estimate_log(log, s);
    } catch (const manip::Error& e) {  // this log is unusable; the others are still processed
      std::cerr << "estimate_impedance: " << e.what() << "\n";
      rc = std::max(rc, e.exit_code());
      continue;
    }
    ++n_readable;
    if (!quiet)
      std::cerr << "estimate_impedance: " << log << ": " << r.n_trials << " trials, " << r.n_perturbed << " perturbed, "
                << r.n_used << " used\n";
    for (const auto& i : r.issues) std::cerr << "estimate_impedance: " << log << ": trial " << i.trial << ": " << i.reason << "\n";
    for (const auto& w : r.warnings) std::cerr << "estimate_impedance: " << log << ": " << w << "\n";
    std::cout << format_text(r, log) << "\n";
    bool flagged = !r.issues.empty();
    bool estimated = false;
    for (const auto& sm : r.summaries)
      if (sm.group.is_session()) {
        estimated = true;
        flagged = flagged || !sm.identifiable;
      }
    any_estimate = any_estimate || estimated;
    if (!estimated) std::cerr << "estimate_impedance: " << log << ": no usable perturbed trial, nothing estimated\n";
    if (flagged) rc = std::max(rc, ec::kPartial);
    try {
      const std::string stem = std::filesystem::path(log).stem().string();
      if (!signals_dir.empty()) export_signals(r, logs.size() > 1 ? signals_dir + "/" + stem : signals_dir);
      if (!plots_dir.empty()) write_plots(r, logs.size() > 1 ? plots_dir + "/" + stem : plots_dir);
    } catch (const manip::Error& e) {
      std::cerr << "estimate_impedance: " << e.what() << "\n";
      rc = std::max(rc, e.exit_code());
    }
    all["sessions"].push_back(to_json(r, log));
    reports.emplace_back(log, std::move(r));
  }
  if (!json_path.empty()) {
    std::ofstream o(json_path);
    if (!(o << all.dump(2) << "\n")) throw manip::OutputError(json_path + ": cannot write JSON");
  }
  if (!csv_path.empty()) write_csv(reports, csv_path);
  // Nothing estimable among the logs that could be read; if none could be
  // read, the input error (4) already says why.
  if (!any_estimate && n_readable > 0) return std::max(rc, ec::kNothing);
  return rc;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const manip::Error& e) {
    std::cerr << "estimate_impedance: " << e.what() << "\n";
    return e.exit_code();
  } catch (const std::exception& e) {
    std::cerr << "estimate_impedance: internal error: " << e.what() << "\n";
    return ec::kInternal;
  }
}
