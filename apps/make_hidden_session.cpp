// make_hidden_session: a "measured" manipulandum session with hidden
// mechanisms (issue 11; include/manip/sim/hidden_effects.hpp), written as an
// ordinary manip LCM log. The log's session message describes the apparatus as
// configured; what was hidden is printed on stderr only (and, with
// --key FILE, written to a separate file), never into the log. Command line:
// common/cli.hpp (docs/cli.md): --version, -q, -o/--out, --force, the
// exit-code table in --help.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "manip/common/cli.hpp"
#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/common/output_file.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/sim/hidden_effects.hpp"
#include "manip/sim/presets.hpp"
#include "manip/version.hpp"

namespace {
// Passes everything but the truth channels (MANIP_TRUTH_STATE,
// MANIP_TRUTH_IMPEDANCE): a log as a lab rig would write it (--no-truth).
class NoTruth final : public manip::logging::SessionHandler {
 public:
  explicit NoTruth(manip::logging::SessionHandler& out) : out_(out) {}
  void on_session(const manip::session_t& m) override { out_.on_session(m); }
  void on_state(const manip::state_t& m) override { out_.on_state(m); }
  void on_trial_event(const manip::trial_event_t& m) override { out_.on_trial_event(m); }
  void on_fault(const manip::fault_t& m) override { out_.on_fault(m); }
  void on_warning(const std::string& w) override { out_.on_warning(w); }

 private:
  manip::logging::SessionHandler& out_;
};

namespace exit_code = manip::exit_code;
// The rows of the one table (common/exit_codes.hpp) make_hidden_session can return.
const std::vector<int> kExitCodes = {exit_code::kOk, exit_code::kUsage, exit_code::kOutput, exit_code::kInternal};
const std::vector<std::string> kNoise = {"none", "quantisation", "motor", "variability", "realistic"};
}  // namespace

static int run(int argc, char** argv) {
  using namespace manip::sim;
  namespace cli = manip::cli;
  CLI::App app{"make_hidden_session " + std::string(manip::kVersion) +
                   ": a simulated session with hidden mechanisms, written as an ordinary log (linear Table-1 person, "
                   "ideal admittance; docs/diagnosis.md). What was hidden goes to stderr (not with -q) and to --key.",
               "make_hidden_session"};
  cli::Common c;
  c.out = "hidden.lcm";
  c.movements = 100;
  std::string key, noise = "realistic";
  std::vector<std::string> hidden;
  std::uint64_t hidden_seed = 1;
  int reps = 3;
  bool no_truth = false;
  cli::add_version(app, "make_hidden_session");
  cli::add_quiet(app, c.quiet);
  cli::add_out(app, c.out, "output LCM log (default hidden.lcm)");
  cli::add_force(app, c.force)->description("replace existing output files (--out and --key)");
  app.add_option("--hidden", hidden,
                 "MECHANISM:MAGNITUDE, SI units, repeatable: delay:0.002 (s) | friction:1 (N) | handle:0.3 (kg) | "
                 "reflex:0.5 (x intrinsic K, D; 25-35 ms) | feedback:0.5 (x intrinsic K, D; 60-100 ms) | reflex_dir:1 (x intrinsic K, D along one direction, only when stretched; 25-35 ms) | curl:40 (N/m) | sensor_lag:0.001 (s, first-order low pass of the "
                 "force sensor) | sensor_offset:2 (N) | sensor_drift:0.05 (N/s). None: a clean session");
  app.add_option("--hidden-seed", hidden_seed, "draw of the session seed, impedance scale, reflex and feedback delays, reflex direction (default 1)");
  app.add_option("--noise", noise, cli::join(kNoise) + " (default realistic)")->check(cli::one_of(kNoise));
  cli::add_movements(app, c.movements, 1, 100000, "number of movements");
  app.add_option("--reps", reps, "perturbed repetitions per angle (default 3)")->check(CLI::Range(1, 1000));
  double pulse_s = 0.15, pulse_n = 15.0;
  cli::add_pulse(app, pulse_s, pulse_n);
  app.add_option("--key", key,
                 "also write what was hidden (text) to this file (an existing file is kept unless --force)");
  app.add_flag("--no-truth", no_truth,
               "leave the truth channels (unperturbed twins, intrinsic and apparent truth) out of the log; the apparent "
               "truth is still printed on stderr (not with -q) and written to --key");
  cli::set_exit_codes(app, kExitCodes);
  if (const auto rc = cli::parse(app, argc, argv)) return *rc;
  std::vector<HiddenEffect> effects;
  for (const auto& h : hidden) effects.push_back(parse_hidden_effect(h));
  SessionDesign base;
  base.n_movements = c.movements;
  base.reps_per_angle = reps;
  base.session.perturbation.duration_s = pulse_s;
  base.session.perturbation.amplitude_n = pulse_n;
  base.session.source = "manip_sim/linear";
  auto person = table1_person();
  try {
    apply_noise(parse_noise_level(noise), base, person);
  } catch (const std::invalid_argument& e) {
    throw manip::UsageError(std::string("--noise: ") + e.what());
  }
  auto hs = make_hidden_session(base, person, effects, hidden_seed);
  try {
    (void)perturbation_schedule(hs.design);
  } catch (const std::invalid_argument& e) {
    throw manip::UsageError(std::string("--movements/--reps: ") + e.what());
  }
  std::ostringstream what;
  what << "hidden:";
  if (effects.empty()) what << " none";
  for (const auto& e : effects) what << " " << to_string(e);
  what << "; hidden seed " << hidden_seed << ": session seed " << hs.draw.session_seed << ", impedance scale "
       << hs.draw.impedance_scale << ", reflex delay " << hs.draw.reflex_delay_s * 1000 << " ms, feedback delay "
       << hs.draw.feedback_delay_s * 1000 << " ms, reflex direction " << hs.draw.reflex_direction_rad * 180.0 / std::numbers::pi
       << " deg, actuation delay "
       << hs.draw.actuation_delay_cycles << " cycles\n";
  // The outputs: written next to their targets and renamed when complete,
  // so an existing file is never truncated; without --force an existing
  // --out or --key is refused here, before the session is simulated.
  if (!key.empty() && std::filesystem::path(key).lexically_normal() == std::filesystem::path(c.out).lexically_normal())
    throw manip::UsageError("--key: '" + key + "' is also the --out log");
  std::string apparent_text;
  manip::AtomicOutput target(c.out, c.force);
  std::optional<manip::AtomicOutput> key_out;
  if (!key.empty()) key_out.emplace(key, c.force);
  const std::string tmp = target.temp_path() + ".lcm";
  {
    manip::logging::LogWritingHandler w(tmp);
    NoTruth filtered(w);
    const auto sum = no_truth ? run_session(hs.design, *hs.person, filtered) : run_session(hs.design, *hs.person, w);
    w.close();
    if (!c.quiet)
      std::cerr << "make_hidden_session: " << sum.trials << " movements, " << sum.perturbed << " perturbed\n";
    if (sum.apparent) {  // the truth an estimator should land on (sim/truth.hpp): the hidden person-side effects are in it
      const auto& ap = *sum.apparent;
      std::ostringstream at;
      at << "apparent truth: D [" << ap.d_nspm(0, 0) << " " << ap.d_nspm(0, 1) << "; " << ap.d_nspm(1, 0) << " "
         << ap.d_nspm(1, 1) << "] N s/m, K [" << ap.k_npm(0, 0) << " " << ap.k_npm(0, 1) << "; " << ap.k_npm(1, 0)
         << " " << ap.k_npm(1, 1) << "] N/m\n";
      if (!c.quiet) std::cerr << "make_hidden_session: " << at.str();
      apparent_text = at.str();
    }
  }
  // Move the finished log over the temporary AtomicOutput holds, then commit.
  std::error_code ec;
  std::filesystem::rename(tmp, target.temp_path(), ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    throw manip::OutputError(c.out + ": cannot be written (" + ec.message() + ")");
  }
  target.commit();
  if (key_out) {
    const std::string text = what.str() + apparent_text;
    if (std::fputs(text.c_str(), key_out->stream()) < 0) throw manip::OutputError(key + ": write failed");
    key_out->commit();
  }
  if (!c.quiet) std::cerr << "make_hidden_session: wrote " << c.out << "; " << what.str();
  return exit_code::kOk;
}

int main(int argc, char** argv) { return manip::cli::run_main("make_hidden_session", run, argc, argv); }
