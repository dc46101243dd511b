// estimate_impedance: involuntary impedance (D, K) of the arm from manip LCM
// logs (paper §3, Table 1). Thin main: options -> estimation library -> outputs.
#include <charconv>
#include <cmath>
#include <filesystem>
#include <iostream>

#include "manip/common/cli.hpp"
#include "manip/common/errors.hpp"
#include "manip/common/temp_dir.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/common/output_file.hpp"
#include "manip/estimation/group.hpp"
#include "manip/estimation/report.hpp"
#include "manip/version.hpp"

namespace {

namespace ec = manip::exit_code;
namespace fs = std::filesystem;

// The rows of the one table (common/exit_codes.hpp) estimate_impedance returns;
// what each means here is in kExitNotes.
const std::vector<int> kExitCodes = {ec::kOk,      ec::kPartial, ec::kUsage,  ec::kConfig,
                                     ec::kInput,   ec::kNothing, ec::kOutput, ec::kInternal};
const char* kExitNotes =
    "What the codes mean for estimate_impedance (several: the most severe wins, docs/exit-codes.md):\n"
    "    0: every log estimated, nothing excluded or flagged\n"
    "    1: estimated, but trials were excluded, a session fit is flagged not identifiable, or a figure\n"
    "       could not be drawn\n"
    "    2: bad command line (unknown option, value not a number or out of range): nothing read\n"
    "    3: settings file (--config) invalid, unreadable or not found\n"
    "    4: a log unusable (missing, not LCM, no/invalid session message, no MANIP_STATE, unknown schema);\n"
    "       other logs still processed\n"
    "    5: no usable perturbed trial in any readable log\n"
    "    6: an output (--json, --csv, --plots, --report, --export-signals) cannot be written: exists\n"
    "       without --force, unwritable, or Python/matplotlib missing for --plots/--report\n";

std::string method_help() {
  std::string t = "Methods (--method; 'all' runs every one):\n";
  for (const auto* m : manip::estimation::registered_methods()) {
    t += "  " + m->name() + ": " + m->description();
    if (m->name() == manip::estimation::default_method()) t += " [default, recommended]";
    if (const auto b = manip::estimation::method_bias_note(m->name()); !b.empty()) t += " [" + b + "]";
    t += "\n";
  }
  return t;
}

// A whole-string finite number, or UsageError naming the option and its range.
double number(const std::string& opt, const std::string& text, double lo, double hi, bool lo_open, const std::string& range) {
  double v = 0;
  const char* b = text.data();
  const char* e = b + text.size();
  const auto [p, err] = std::from_chars(b, e, v);
  if (err != std::errc() || p != e || !std::isfinite(v))
    throw manip::UsageError(opt + " " + text + ": not a finite number (expected " + range + ")");
  if ((lo_open ? !(v > lo) : !(v >= lo)) || !(v <= hi)) throw manip::UsageError(opt + " " + text + ": out of range (expected " + range + ")");
  return v;
}

int integer(const std::string& opt, const std::string& text, int lo, int hi) {
  int v = 0;
  const char* b = text.data();
  const char* e = b + text.size();
  const auto [p, err] = std::from_chars(b, e, v);
  const std::string range = "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
  if (err != std::errc() || p != e) throw manip::UsageError(opt + " " + text + ": not an integer (expected " + range + ")");
  if (v < lo || v > hi) throw manip::UsageError(opt + " " + text + ": out of range (expected " + range + ")");
  return v;
}

// Refuses an existing output before any log is read (the write itself checks again, atomically).
void check_new_file(const std::string& opt, const std::string& path, bool force) {
  std::error_code e;
  if (!force && fs::exists(path, e))
    throw manip::OutputError(opt + " " + path + ": exists (pass --force to overwrite it); nothing was read");
}

void check_dir(const std::string& opt, const std::string& dir, bool force) {
  std::error_code e;
  if (!force && fs::is_directory(dir, e) && !fs::is_empty(dir, e))
    throw manip::OutputError(opt + " " + dir + ": exists and is not empty (pass --force to overwrite its files); nothing was read");
  if (fs::exists(dir, e) && !fs::is_directory(dir, e)) throw manip::OutputError(opt + " " + dir + ": exists and is not a directory");
}


int run(int argc, char** argv) {
  using namespace manip::estimation;
  namespace cli = manip::cli;
  CLI::App app{"estimate_impedance " + std::string(manip::kVersion) +
                   ": involuntary impedance (damping D, stiffness K) from manip session logs.",
               "estimate_impedance"};
  app.footer(method_help() + "\n" + kExitNotes);
  std::vector<std::string> logs;
  std::string method = default_method(), cutoff = "1", json_path, csv_path, signals_dir, plots_dir, report_path,
              group_csv_path;
  // Numbers are read as text and parsed here, so a bad value is refused with
  // the option named and its range (not CLI11's or std::stod's wording).
  std::string t_est, cutoff_thr, oe_pre, sg_window, oe_poly;
  std::string k_model, force_source, position_source;
  bool estimate_m = false, no_jackknife = false, group = false;
  cli::Common c;
  cli::add_version(app, "estimate_impedance");
  cli::add_quiet(app, c.quiet);
  app.add_option("logs", logs, "LCM log files (one session each)")->required();
  app.add_option("--method", method, method_list() + " | all (default " + default_method() + ", listed below)");
  app.add_option("--cutoff", cutoff, "high-pass cut-off in Hz, (0, 100], or 'auto' from the jerk PSDs (default 1, paper §4.3)");
  app.add_option("--cutoff-threshold-db", cutoff_thr, "perturbed/unperturbed PSD ratio for --cutoff auto, (0, 60] dB (default 3)");
  app.add_option("--t-est", t_est, "estimation window after onset, (0, 1] s (default 0.15)");
  app.add_option("--sg-window", sg_window, "Savitzky-Golay window in samples, odd, [7, 100001] (default: -3 dB at 30 Hz, 225 at 4 kHz)");
  app.add_option("--k-model", k_model, "symmetric (eq. 30) | full (8 parameters) for paper methods");
  app.add_flag("--estimate-m", estimate_m, "estimate M too (eq. 24-29) in paper methods instead of M_BSP");
  app.add_option("--force-source", force_source, "admittance (eq. 21) | sensor: Δu_ext for paper methods");
  app.add_option("--position-source", position_source,
                 "auto (default): the reference on manip_rt logs, the encoder otherwise | encoder (measured) | reference: the "
                 "admittance's x_ref aligned to the encoder, for every method (exact in eq. 21 when the stages track it through "
                 "a PD) | tracked: the encoder, with the tracking error x_ref - x as a known force on the loop "
                 "(docs/estimator.md, \"Which position\")");
  app.add_option("--oe-pre", oe_pre, "output error: data before onset, [0, 0.5] s (default 0.05)");
  app.add_option("--oe-poly-order", oe_poly, "output error: per-trial polynomial order, [0, 8] (default 3)");
  app.add_flag("--no-jackknife", no_jackknife, "output error: least-squares SE instead of the jackknife over trials");
  cli::add_config(app, c.config, "estimator.yaml",
                  "estimator settings YAML, read only when given (else built-in defaults); flags override it");
  app.add_option("--json", json_path, "write results as JSON (layout: docs/estimator.md)");
  app.add_option("--csv", csv_path, "write results as CSV, tidy long form (docs/estimator.md)");
  app.add_option("--export-signals", signals_dir, "write per-trial Δ signals as CSV into DIR");
  app.add_option("--plots", plots_dir, "draw the figures (python -m manipplot.plots, docs/report.md) into DIR (DIR/<log stem>/ for several logs)");
  app.add_option("--report", report_path, "write the HTML session report (python -m manipplot.report; one page, group table first for several logs)");
  app.add_flag("--group", group, "group table (Table 1: mean (std) over participants); always on with several logs");
  app.add_option("--group-csv", group_csv_path, "write the group table as CSV, tidy long form");
  cli::add_force(app, c.force);
  cli::set_exit_codes(app, kExitCodes);
  if (const auto rc = cli::parse(app, argc, argv)) return *rc;
  const bool quiet = c.quiet, force = c.force;
  // A bare name (--config lab.yaml) is searched like every program's config (docs/cli.md).
  const std::string config = c.config.empty() ? std::string() : cli::find_config(c.config, "estimator.yaml");

  // Every option is checked before any log is read.
  EstimatorSettings s;
  if (!config.empty()) s = load_estimator_settings(config, s);  // ConfigError: exit 3
  auto given = [&](const char* name) { return !app.get_option(name)->empty(); };
  if (method == "all") s.methods = all_methods();
  else if (given("--method") || config.empty()) s.methods = {method};
  if (given("--cutoff") || config.empty()) {
    if (cutoff == "auto") {
      s.cutoff_auto = true;
    } else {
      s.cutoff_auto = false;
      s.pipeline.hp_cutoff_hz = number("--cutoff", cutoff, 0.0, kMaxCutoffHz, true, "a frequency in (0, 100] Hz or 'auto'");
    }
  }
  if (given("--cutoff-threshold-db")) s.cutoff_auto_threshold_db = number("--cutoff-threshold-db", cutoff_thr, 0.0, 60.0, true, "(0, 60] dB");
  if (given("--t-est")) s.pipeline.t_est_s = s.oe.t_est_s = s.pem.t_est_s = number("--t-est", t_est, 0.0, 1.0, true, "(0, 1] s");
  if (given("--sg-window")) {
    const int w = integer("--sg-window", sg_window, kMinSgWindow, kMaxSgWindow);
    if (w % 2 == 0) throw manip::UsageError("--sg-window " + sg_window + ": must be odd");
    s.pipeline.sg_window = w;
  }
  if (!k_model.empty()) {
    if (k_model == "symmetric") s.ls.k_model = StiffnessModel::symmetric;
    else if (k_model == "full") s.ls.k_model = StiffnessModel::full;
    else throw manip::UsageError("--k-model " + k_model + ": expected symmetric or full");
  }
  if (estimate_m) s.ls.estimate_m = true;
  if (!force_source.empty()) {
    if (force_source == "admittance") s.ls.force = ForceSource::admittance;
    else if (force_source == "sensor") s.ls.force = ForceSource::sensor;
    else throw manip::UsageError("--force-source " + force_source + ": expected admittance or sensor");
  }
  if (!position_source.empty()) {
    const auto p = parse_position_source(position_source);
    if (!p) throw manip::UsageError("--position-source " + position_source + ": expected auto, encoder, reference or tracked");
    s.position = *p;
  }
  if (given("--oe-pre")) s.oe.t_pre_s = number("--oe-pre", oe_pre, 0.0, 0.5, false, "[0, 0.5] s");
  if (given("--oe-poly-order")) s.oe.poly_order = integer("--oe-poly-order", oe_poly, 0, 8);
  if (no_jackknife) s.oe.jackknife = false;
  s.keep_windows = !signals_dir.empty() || !plots_dir.empty() || !report_path.empty();
  try {
    SessionEstimator probe(s);  // validates method names
  } catch (const std::invalid_argument& e) {
    throw manip::UsageError(std::string("--method: ") + e.what());
  }
  // Outputs: refused before the (long) estimation if they would clobber a file.
  if (!json_path.empty()) check_new_file("--json", json_path, force);
  if (!csv_path.empty()) check_new_file("--csv", csv_path, force);
  if (!group_csv_path.empty()) check_new_file("--group-csv", group_csv_path, force);
  if (!report_path.empty()) check_new_file("--report", report_path, force);
  if (!plots_dir.empty()) check_dir("--plots", plots_dir, force);
  if (!signals_dir.empty()) check_dir("--export-signals", signals_dir, force);
  // Python/matplotlib are checked when drawing (render_plots): if missing, the
  // estimates are still printed and written, the figures named as not drawn (exit 6).

  int rc = ec::kOk;
  int n_readable = 0;
  bool any_estimate = false;
  std::vector<std::pair<std::string, Report>> reports;
  nlohmann::json all = {{"manip_version", manip::kVersion},
                        {"default_method", default_method()},
                        {"settings", settings_to_json(s)},
                        {"sessions", nlohmann::json::array()}};
  // Signals for --plots/--report when the user did not ask for them: a temporary directory.
  std::optional<manip::ScopedTempDir> tmp;
  if ((!plots_dir.empty() || !report_path.empty()) && (signals_dir.empty() || json_path.empty())) tmp.emplace("estimate_impedance");
  const std::string sig_root = !signals_dir.empty() ? signals_dir : (tmp ? (tmp->path() / "signals").string() : std::string());
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
    // The reader's warnings already start with the file name (and byte offset).
    for (const auto& w : r.warnings)
      std::cerr << "estimate_impedance: " << (w.rfind(log + ": ", 0) == 0 ? w : log + ": " + w) << "\n";
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
    if (!sig_root.empty()) {
      try {
        const std::string stem = fs::path(log).stem().string();
        export_signals(r, logs.size() > 1 ? sig_root + "/" + stem : sig_root, force);
      } catch (const manip::Error& e) {
        std::cerr << "estimate_impedance: " << e.what() << "\n";
        rc = std::max(rc, e.exit_code());
      }
    }
    all["sessions"].push_back(to_json(r, log));
    r.windows.clear();  // the signals are written; keep memory bounded over many logs
    reports.emplace_back(log, std::move(r));
  }
  // Group table (Table 1 over participants): several logs, or --group.
  std::vector<GroupTable> groups;
  if ((group || reports.size() > 1) && !reports.empty()) {
    groups = group_tables(reports, s.methods);
    std::cout << group_text(groups);
    all["group"] = group_json(groups)["groups"];
  }
  auto output = [&](const std::function<void()>& f) {
    try {
      f();
    } catch (const manip::Error& e) {
      std::cerr << "estimate_impedance: " << e.what() << "\n";
      rc = std::max(rc, e.exit_code());
    }
  };
  if (!json_path.empty()) output([&] { manip::write_file_atomically(json_path, all.dump(2) + "\n", force); });
  if (!csv_path.empty()) output([&] { write_csv(reports, csv_path, force); });
  if (!group_csv_path.empty()) output([&] { manip::write_file_atomically(group_csv_path, group_csv(groups), force); });
  if ((!plots_dir.empty() || !report_path.empty()) && !reports.empty()) {
    std::string results = json_path;
    if (results.empty() || rc == ec::kOutput) {
      results = (tmp->path() / "results.json").string();
      output([&] { manip::write_file_atomically(results, all.dump(1) + "\n", true); });
    }
    // --log: the log itself, or (several logs) a directory of links to them.
    std::string log_arg;
    if (reports.size() == 1) {
      log_arg = reports.front().first;
    } else if (tmp) {
      const fs::path d = tmp->path() / "logs";
      std::error_code e;
      fs::create_directories(d, e);
      for (const auto& [log, r] : reports) fs::create_symlink(fs::absolute(log, e), d / fs::path(log).filename(), e);
      log_arg = d.string();
    }
    const RenderInputs in{results, sig_root, log_arg, ""};
    auto notes = [&](const RenderResult& res) {
      for (const auto& n : res.notes) std::cerr << "estimate_impedance: " << n << "\n";
      if (res.manipplot_exit != 0) rc = std::max(rc, ec::kPartial);
    };
    if (!plots_dir.empty()) output([&] { notes(render_plots(in, plots_dir, force)); });
    if (!report_path.empty()) output([&] { notes(render_report({results}, in, report_path, force)); });
  }
  // Nothing estimable among the logs that could be read; if none could be
  // read, the input error (4) already says why.
  if (!any_estimate && n_readable > 0) return std::max(rc, ec::kNothing);
  return rc;
}

}  // namespace

int main(int argc, char** argv) { return manip::cli::run_main("estimate_impedance", run, argc, argv); }
