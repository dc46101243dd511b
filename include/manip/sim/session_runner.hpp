#pragma once
// Simulated lab sessions on the ideal admittance, written as the same message
// stream a lab log holds (session message, 4 kHz state, trial events), plus the
// unperturbed twin of every perturbed trial (MANIP_TRUTH_STATE, same cycle
// numbers) and the ground-truth impedance (MANIP_TRUTH_IMPEDANCE): per perturbed
// trial the intrinsic one (model = the human's TruthSource::truth_model()), and
// with the last perturbed trial one apparent impedance for the session (model
// "apparent", trial -1; sim/truth.hpp).
// Each perturbed trial is simulated twice with the same seed: unperturbed
// (the twin) and perturbed; Δ = perturbed - twin is the true variational
// dynamics.
//
// What the runner shares with the controller (so a simulated log means what a
// lab log means): the trial schedule (control::make_schedule), the perturbation
// trigger (control::PerturbationTrigger: first crossing of x2 = trigger while
// moving towards the goal), the phase and mode codes (schema/codes.hpp), the
// session description (schema::SessionDescription, sent with schema::to_message)
// and the portable RNG (common/rng.hpp), so a seed reproduces the log with any
// standard library.
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "manip/common/perturbation.hpp"
#include "manip/control/protocol.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/schema/session_description.hpp"
#include "manip/sim/human.hpp"
#include "manip/sim/ideal_admittance.hpp"
#include "manip/sim/truth.hpp"

namespace manip::sim {

// manip_sim's session description: the schema defaults (paper §5.1 apparatus,
// 0.25 kg handle) with the simulator's ids; the ideal admittance has no drive
// downsampling, so the drive rate equals the sample rate.
schema::SessionDescription default_sim_session();

struct SessionDesign {
  // Admittance, handle mass, frame, anthropometrics, perturbation design
  // (T_pert, A_pert, trigger line), sample rate and ids: the one description,
  // sent as the log's session message and used as the simulated plant.
  schema::SessionDescription session{default_sim_session()};
  int substeps{4};                        // integration steps per sample (semi-implicit Euler at 16 kHz)
  bool midpoint_plant{false};             // step_ideal_admittance(..., midpoint): manip_sim's neuromech arm at 4 kHz
  int n_movements{100};                   // paper §5.2
  std::vector<double> angles_deg{30, 60, 120, 150, 210, 240, 300, 330};  // paper §4.2
  int reps_per_angle{3};                  // 8 x 3 = 24 perturbed (paper §5.2)
  bool write_twins{true};                 // MANIP_TRUTH_STATE for perturbed trials
  // Hidden apparatus mechanisms (sim/hidden_effects.hpp). The session message
  // (and the log) keep the configured apparatus; the plant has these.
  int actuation_delay_cycles{0};          // u_pert reaches the plant this many cycles after it is logged
  double hidden_handle_extra_kg{0.0};     // plant handle mass = configured + this, both axes
  double hidden_stage_friction_n{0.0};    // Coulomb per workspace axis: -F tanh(v_axis / 1 mm/s)
  // Handle force sensor: reading = LP_tau(force) + offset + drift t (t = cycle / rate;
  // offset and drift on both workspace axes). The admittance renders from the
  // reading, the log records it (plus force_noise_n, log only as before).
  double hidden_sensor_lag_s{0.0};        // first-order low pass time constant tau
  double hidden_sensor_offset_n{0.0};
  double hidden_sensor_drift_nps{0.0};
  bool write_apparent_truth{true};        // session-level MANIP_TRUTH_IMPEDANCE, model "apparent", trial -1 (sim/truth.hpp)
  Vec2 start_shoulder_m{0.0, 0.30};
  Vec2 goal_shoulder_m{0.0, 0.55};
  double reach_duration_s{3.0};
  double reach_duration_jitter_s{0.0};    // uniform +- jitter
  double lateral_bow_std_m{0.0};          // path variation, normal std
  double rest_before_s{0.5};              // in the start target before the go cue (inside the trial)
  double rest_after_s{0.5};               // in the goal target before END
  double return_s{0.8};                   // return movement between trials (trial = -1)
  // GOAL_HOLD is logged while the measured hand rests in the goal target: the
  // controller's criterion (control::Protocol::in_goal) with its default radius
  // and speed (config/rt.yaml protocol.target_radius_m, rest_speed_mps).
  double target_radius_m{0.01};
  double rest_speed_mps{0.01};
  double encoder_resolution_m{1e-6};      // paper §5.1; 0 = no quantisation
  double force_noise_n{0.0};              // force-sensor white noise std per axis
  double t_est_s{0.15};                   // window over which the truth is averaged
  std::uint64_t seed{1};                  // schedule (control::make_schedule), reaches, sensor noise, human noise

  [[nodiscard]] PerturbationProfile perturbation() const {
    return PerturbationProfile{session.perturbation.duration_s, session.perturbation.amplitude_n};
  }
};

struct SessionRunSummary {
  int trials{0};
  int perturbed{0};
  int onsets{0};
  std::int64_t cycles{0};
  std::vector<double> max_dev_x1_m, max_dev_x2_m;  // per perturbed trial, |Δx| max within [0, T_est]
  std::optional<ApparentImpedance> apparent;        // the session's apparent truth (sim/truth.hpp), if determined
};

// Runs the whole session into `out`. The human is reset per trial via begin_trial.
// Throws std::invalid_argument for a design that cannot run.
SessionRunSummary run_session(const SessionDesign& design, HumanModel& human, logging::SessionHandler& out);

// The perturbed/unperturbed schedule the runner uses: the controller's
// (control::make_schedule with the design's seed), so a seed gives the same
// schedule in manip_sim and manip_rt.
std::vector<control::TrialSpec> perturbation_schedule(const SessionDesign& design);

}  // namespace manip::sim
