// manip_sim: a simulated lab session (paper §4) written as a manip LCM log,
// in the same schema as manip_rt's, so estimate_impedance runs on it unchanged.
#include <CLI/CLI.hpp>
#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <memory>
#include <numeric>

#include <fstream>
#include <iomanip>
#include <sstream>

#include "manip/estimation/isolation_model.hpp"
#include "manip/estimation/report.hpp"
#include "manip/estimation/validation.hpp"
#include "manip/common/cli.hpp"
#include "manip/common/errors.hpp"
#include "manip/common/output_file.hpp"
#include "manip/sim/human_factory.hpp"
#include "manip/sim/presets.hpp"
#include "manip/sim/session_runner.hpp"
#include "manip/version.hpp"

namespace {
namespace exit_code = manip::exit_code;
// The rows of the one table (common/exit_codes.hpp) manip_sim can return.
const std::vector<int> kExitCodes = {exit_code::kOk, exit_code::kUsage, exit_code::kConfig, exit_code::kOutput,
                                     exit_code::kInternal};
const std::vector<std::string> kNoise = {"none", "quantisation", "motor", "variability", "realistic"};
const std::vector<std::string> kFeedback = {"config", "intrinsic", "short-latency"};
const std::vector<std::string> kPersons = {"table1", "stiff"};
}  // namespace

int run(int argc, char** argv) {
  using namespace manip::sim;
  namespace cli = manip::cli;
  std::string models_help;
  for (const auto& m : human_models()) models_help += (models_help.empty() ? "" : " | ") + m.name + " (" + m.description + ")";
  CLI::App app{"manip_sim " + std::string(manip::kVersion) +
                   ": simulate a perturbation session on the ideal admittance and write it as a manip LCM log.",
               "manip_sim"};
  cli::Common c;
  c.out = "session.lcm";
  c.movements = 100;
  std::string human = "linear", noise = "realistic", person = "table1", arm_config_old;
  int reps = 3;
  std::uint64_t seed = 1;
  cli::add_version(app, "manip_sim");
  cli::add_quiet(app, c.quiet);
  cli::add_out(app, c.out, "output LCM log (default session.lcm)");
  cli::add_force(app, c.force);
  // Checked by make_human (before any output): "unknown human model 'x'" naming the known ones.
  app.add_option("--human", human, "human model: " + models_help);
  app.add_option("--person", person, "linear human: table1 (paper Table 1) | stiff")->check(cli::one_of(kPersons));
  cli::add_config(app, c.config, "arm_model.yaml", "neuromechanical parameters YAML (read with --human neuromech)");
  app.add_option("--arm-config", arm_config_old, "deprecated alias of --config");
  std::string feedback = "config";
  app.add_option("--feedback", feedback,
                 "neuromech: config (as in the YAML) | intrinsic (all feedback pathways off: the ground-truth case) | "
                 "short-latency (only the short-latency reflex on)")
      ->check(cli::one_of(kFeedback));
  app.add_option("--noise", noise, cli::join(kNoise) + " (default realistic; docs/accuracy-study.md)")
      ->check(cli::one_of(kNoise));
  cli::add_movements(app, c.movements, 1, 100000, "number of movements (paper §5.2)");
  app.add_option("--reps", reps, "perturbed repetitions per angle (default 3: 24 perturbed trials; 0: none)")
      ->check(CLI::Range(0, 10000));
  app.add_option("--seed", seed, "random seed (schedule as in manip_rt's protocol.seed, reaches, noise)");
  double pulse_s = 0.15, pulse_n = 15.0;
  cli::add_pulse(app, pulse_s, pulse_n);
  std::string validate_dir;
  app.add_option("--validate", validate_dir,
                 "after writing, validate against the twin truth (paper §4.3: Fig. 3 PSDs, Fig. 4 NRMSE, max "
                 "deviations, estimates vs ground truth) into DIR (text, JSON, SVG)");
  cli::set_exit_codes(app, kExitCodes);
  if (const auto rc = cli::parse(app, argc, argv)) return *rc;
  if (!arm_config_old.empty()) {
    std::cerr << "manip_sim: --arm-config is deprecated; use --config\n";
    if (c.config.empty()) c.config = arm_config_old;
  }
  const std::string& out = c.out;
  SessionDesign d;
  BuiltHuman built;
  try {
    d.n_movements = c.movements;
    d.reps_per_angle = reps;
    d.seed = seed;
    d.session.perturbation.duration_s = pulse_s;
    d.session.perturbation.amplitude_n = pulse_n;
    HumanSpec spec;
    spec.model = human;
    spec.sample_rate_hz = d.session.sample_rate_hz;
    spec.linear = person == "stiff" ? stiff_person() : table1_person();
    spec.feedback = feedback;
    // The neuromech model reads its parameters from arm_model.yaml found on the
    // search path (common/cli.hpp), so an installed manip_sim runs from any directory.
    if (human == "neuromech" || !c.config.empty()) spec.arm_config = cli::find_config(c.config, "arm_model.yaml");
    NoiseLevel level{};
    try {
      level = parse_noise_level(noise);
    } catch (const std::invalid_argument& e) {
      throw manip::UsageError(std::string("--noise: ") + e.what());
    }
    apply_noise(level, d, spec.linear);
    built = make_human(spec);
    d.substeps = static_cast<int>(std::lround(1.0 / (built.step_s * d.session.sample_rate_hz)));
    if (d.substeps < 1) throw manip::UsageError("--human " + human + ": plant step longer than a sample");
    d.midpoint_plant = built.midpoint_plant;
    if (built.anthropometrics) d.session.anthropometrics = *built.anthropometrics;
    d.session.config_yaml = built.config_yaml;
    d.session.source = "manip_sim/" + human;
    d.session.session_id = "sim-seed" + std::to_string(seed);
    (void)perturbation_schedule(d);  // refuses a design that cannot run (e.g. more perturbed trials than movements)
  } catch (const manip::Error& e) {
    std::cerr << "manip_sim: " << e.what() << "\n";
    return e.exit_code();
  } catch (const std::invalid_argument& e) {
    std::cerr << "manip_sim: " << e.what() << "\n";
    return exit_code::kUsage;
  }
  try {
    if (const auto dir = std::filesystem::path(out).parent_path(); !dir.empty()) std::filesystem::create_directories(dir);
    // Written to a temporary beside the target and renamed on success: an
    // existing log is never replaced without --force, and a run that fails
    // leaves the target as it was and no temporary behind (common/output_file.hpp).
    manip::AtomicOutput target(out, c.force);
    SessionRunSummary sum;
    {
      manip::logging::LogWritingHandler w(target.temp_path());
      sum = run_session(d, *built.model, w);
      w.close();
    }
    // mkstemp creates the temporary 0600; a session log is shared like any
    // file the user creates (mode 0666 minus the umask).
    const mode_t mask = ::umask(0);
    ::umask(mask);
    ::chmod(target.temp_path().c_str(), 0666 & ~mask);
    target.commit();
    auto mean = [](const std::vector<double>& v) {
      return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
    };
    if (!c.quiet)
      std::cerr << "manip_sim: wrote " << out << ": " << sum.trials << " movements, " << sum.perturbed << " perturbed ("
              << sum.onsets << " onsets), " << sum.cycles << " cycles; mean max deviation in [0, "
              << d.t_est_s * 1000 << "] ms: x1 " << mean(sum.max_dev_x1_m) * 1000 << " mm, x2 "
              << mean(sum.max_dev_x2_m) * 1000 << " mm\n";
    if (sum.apparent && !c.quiet) {  // the session's apparent (involuntary) impedance truth, sim/truth.hpp
      const auto& ap = *sum.apparent;
      std::cerr << "manip_sim: apparent truth (intrinsic + feedback within " << d.t_est_s * 1000 << " ms): D [" << ap.d_nspm(0, 0)
                << " " << ap.d_nspm(0, 1) << "; " << ap.d_nspm(1, 0) << " " << ap.d_nspm(1, 1) << "] N s/m, K ["
                << ap.k_npm(0, 0) << " " << ap.k_npm(0, 1) << "; " << ap.k_npm(1, 0) << " " << ap.k_npm(1, 1) << "] N/m\n";
    }
    if (!validate_dir.empty()) {
      namespace est = manip::estimation;
      est::EstimatorSettings es;
      es.methods = est::all_methods();
      es.keep_windows = true;
      const auto rep = est::estimate_log(out, es);
      const auto curves = est::nrmse_curves(rep.windows);
      // Beside the paper's isolation, the model-based one (isolation_model.hpp).
      est::ModelIsolationSettings mis;
      mis.oe = es.oe;
      mis.pem = es.pem;
      mis.pipeline = es.pipeline;
      const auto iso = est::isolate_model_based_log(out, mis);
      const auto curves_model = est::nrmse_curves(iso.windows, 0.15, 30, "model-based");
      std::filesystem::create_directories(validate_dir);
      std::ostringstream txt;
      txt << "manip_sim validation of " << out << " (" << d.session.source << ", seed " << seed << ")\n"
          << "max deviation in [0, " << d.t_est_s * 1000 << "] ms, mean (std) over " << sum.max_dev_x1_m.size()
          << " perturbed trials: x1 ";
      auto ms = [](const std::vector<double>& v) {
        double m = 0, s2 = 0;
        for (double x : v) m += x / static_cast<double>(v.size());
        for (double x : v) s2 += (x - m) * (x - m) / std::max<double>(1.0, static_cast<double>(v.size()) - 1.0);
        std::ostringstream o;
        o << std::fixed << std::setprecision(2) << m * 1000 << " (" << std::sqrt(s2) * 1000 << ") mm";
        return o.str();
      };
      txt << ms(sum.max_dev_x1_m) << ", x2 " << ms(sum.max_dev_x2_m) << "   (paper §4.2: 6.1 (1.8) mm, 5.9 (1.7) mm)\n"
          << "jerk PSD (Fig. 3): unperturbed peak " << rep.psd.peak_unperturbed_hz << " Hz (paper: 0.6385 Hz from recorded "
          << "movements), first frequency with perturbed/unperturbed > 3 dB: " << rep.psd.cutoff_auto_hz << " Hz\n"
          << est::format_text(curves) << est::format_text(curves_model) << "\n"
          << est::format_text(rep, out);
      manip::write_file_atomically(validate_dir + "/validation.txt", txt.str(), c.force);
      nlohmann::json j = {{"nrmse", est::to_json(curves)}, {"nrmse_model_based", est::to_json(curves_model)},
                          {"estimate", est::to_json(rep, out)},
                          {"max_dev_x1_m", sum.max_dev_x1_m}, {"max_dev_x2_m", sum.max_dev_x2_m}};
      manip::write_file_atomically(validate_dir + "/validation.json", j.dump(1) + "\n", c.force);
      est::write_nrmse_plot(curves, validate_dir + "/fig4_nrmse.svg");
      est::write_nrmse_plot(curves_model, validate_dir + "/fig4_nrmse_model_based.svg");
      est::write_plots(rep, validate_dir);
      std::cout << txt.str();
    }
  } catch (const manip::Error& e) {
    std::cerr << "manip_sim: " << e.what() << "\n";
    return e.exit_code();
  } catch (const std::exception& e) {
    // The log writer and the report writers throw std::runtime_error naming the file.
    std::cerr << "manip_sim: " << e.what() << "\n";
    return exit_code::kOutput;
  }
  return exit_code::kOk;
}

int main(int argc, char** argv) { return manip::cli::run_main("manip_sim", run, argc, argv); }
