#pragma once
// Simulated lab sessions on the ideal admittance, written as the same message
// stream a lab log holds (session message, 4 kHz state, trial events), plus the
// unperturbed twin of every perturbed trial (MANIP_TRUTH_STATE, same cycle
// numbers) and the ground-truth impedance (MANIP_TRUTH_IMPEDANCE).
// Each perturbed trial is simulated twice with the same seed: unperturbed
// (the twin) and perturbed; Δ = perturbed - twin is the true variational
// dynamics.
#include <cstdint>
#include <string>
#include <vector>

#include "manip/common/frames.hpp"
#include "manip/common/perturbation.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/model/arm.hpp"
#include "manip/sim/human.hpp"
#include "manip/sim/ideal_admittance.hpp"

namespace manip::sim {

struct SessionDesign {
  double sample_rate_hz{4000.0};
  int substeps{4};                        // integration steps per sample (semi-implicit Euler at 16 kHz)
  bool midpoint_plant{false};             // step_ideal_admittance(..., midpoint): manip_sim's neuromech arm at 4 kHz
  int n_movements{100};                   // paper §5.2
  std::vector<double> angles_deg{30, 60, 120, 150, 210, 240, 300, 330};  // paper §4.2
  int reps_per_angle{3};                  // 8 x 3 = 24 perturbed (paper §5.2)
  bool write_twins{true};                 // MANIP_TRUTH_STATE for perturbed trials
  Vec2 start_shoulder_m{0.0, 0.30};
  Vec2 goal_shoulder_m{0.0, 0.55};
  double trigger_x2_shoulder_m{0.40};
  PerturbationProfile perturbation{};
  double reach_duration_s{3.0};
  double reach_duration_jitter_s{0.0};    // uniform +- jitter
  double lateral_bow_std_m{0.0};          // path variation, normal std
  double rest_before_s{0.5};              // in the start target before the go cue (inside the trial)
  double rest_after_s{0.5};               // in the goal target before END
  double return_s{0.8};                   // return movement between trials (trial = -1)
  double encoder_resolution_m{1e-6};      // paper §5.1; 0 = no quantisation
  double force_noise_n{0.0};              // force-sensor white noise std per axis
  double t_est_s{0.15};                   // window over which the truth is averaged
  AdmittanceParams admittance{};
  WorkspaceToShoulder frame{};
  Anthropometrics anthropometrics{};
  std::uint64_t seed{1};
  std::string source{"manip_sim"};
  std::string participant_id{"sim"};
  std::string session_id{"sim-0"};
  std::string config_yaml;
};

struct SessionRunSummary {
  int trials{0};
  int perturbed{0};
  int onsets{0};
  std::int64_t cycles{0};
  std::vector<double> max_dev_x1_m, max_dev_x2_m;  // per perturbed trial, |Δx| max within [0, T_est]
};

// Runs the whole session into `out`. The human is reset per trial via begin_trial.
SessionRunSummary run_session(const SessionDesign& design, HumanModel& human, logging::SessionHandler& out);

// The perturbed/unperturbed schedule the runner uses: for each movement the
// perturbation angle in degrees, or NaN if unperturbed. Deterministic per seed.
std::vector<double> perturbation_schedule(const SessionDesign& design);

}  // namespace manip::sim
