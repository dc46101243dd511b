#pragma once
// Neuromechanical model of the human arm holding the handle (paper §2 eq. 1-5,
// §4.1 eq. 33-35; Franklin et al. 2008, Tee et al. 2004), extended with
// separately switchable reflex pathways and an analytic ground truth of the
// involuntary impedance. Shoulder frame (docs/conventions.md), SI units.
//
// Model, per simulation step n (t_n = n * step_s):
//   plan         x_d(t) minimum-jerk (ReachSpec), q_d = IK(x_d), qd_d = J^-1 xd_d,
//                qdd_d = J^-1 (xdd_d - Jd qd_d)
//   feed-forward tau_ff = M_q(q_d) qdd_d + C(q_d, qd_d) + J^T (M_load xdd_d + D_load xd_d)
//                (inverse dynamics of the plan on the expected load, i.e. the admittance
//                M_adm + M_handle, D_adm), distributed over the six muscles as
//                a_ff = argmin |a - a_tonic|^2  s.t.  A a = tau_ff, a >= 0
//                (minimum deviation from a tonic co-contraction; A = moment arms)
//   muscle error e_m = lambda - lambda_d = -A^T (q - q_d), ed_m = -A^T (qd - qd_d)
//                (constant moment arms: length lambda = lambda_0 - A^T q)
//   feedback     u = a_ff + sum over enabled pathways p of
//                      kp_p e_m(t_n - delay_p) + kd_p ed_m(t_n - delay_p)     (eq. 4)
//                short-latency stretch reflex, long-latency reflex, voluntary; each
//                homonymous (a muscle responds to its own stretch), own delay and gains
//   noise        a = max(0, u + (sigma_0 + cv * max(0, u)) .* nu)            (eq. 3)
//                nu: per-muscle Ornstein-Uhlenbeck process (zero-mean, unit stationary
//                variance, correlation time tau, exact update per step, started in its
//                stationary distribution): Brownian motion with mean reversion, so the
//                noise is zero-mean and bounded over a trial; signal-dependent via cv.
//                nu comes from manip::PortableRng seeded by begin_trial's seed: paired runs
//                share nu exactly (its amplitude follows each run's own command).
//                Activations are in tension units [N] (eq. 33: m_A = a).
//   tension      m = max(0, a + D_m ed_m + K_m e_m),  K_m = K0 + K1 a,  D_m = K_m / r
//                (eq. 33-35, r = 12 in the paper). A muscle cannot push: a slack muscle
//                has zero tension, stiffness and damping.
//   arm          M_q qdd + C(q, qd) = A m + J^T u_ext                          (eq. 1-2)
//   endpoint     M_x xdd = h + u_ext,  M_x = J^-T M_q J^-1,
//                h = J^-T (A m - C) + M_x Jd qd
//
// Integration (stated, fixed-step): the plant computes xdd from endpoint_dynamics()
// (or endpoint_dynamics_for_step()) and calls advance(dt, xdd) with xdd held over dt.
// The model step step_s is the rate of the neural state: plan, delay lines and noise
// advance once per step, and delays are whole numbers of steps (checked when the
// parameters are loaded). dt may be k * step_s (k >= 1: k steps with xdd held) or
// step_s / m (m >= 2: the plant sub-steps the model; the mechanics follow every
// sub-step, the neural state every m-th). Two steps are configured: step_s = 1/16 kHz
// for manip_rt's sim backend (4 kHz loop x 4 substeps, explicit plant step; its
// start-up check wants dt a whole multiple of step_s), and session_step_s = 1/4 kHz,
// which manip_sim's session runner uses (one step per cycle with the midpoint plant
// step). The mechanical update over h (= step_s or dt) is exact for the held
// acceleration ("trapezoidal" position update):
//   qdd = J^-1 (xdd - Jd qd);  qd' = qd + h qdd;  q' = q + h (qd + qd') / 2
// With forces from the start of the step (endpoint_dynamics, explicit) the error is
// first order: an h/2 delay of the muscle and admittance forces, which acts like a
// mass error of -h/2 (D + D_adm). endpoint_dynamics_for_step(dt) removes it: the
// muscles' stiffness and damping forces are taken at the middle of the step,
// linearised about its start (M_eff = M_x + dt/2 J^-T Dq J^-1, h_eff = h - dt/2 J^-T
// [Kq (qd - qd_d) - Dq (J^-1 Jd qd + qdd_d)]), and step_ideal_admittance(...,
// midpoint = true) does the same for D_adm. At 4 kHz that moves impedance estimates
// on simulated logs by < 0.5 % against a 1/64 kHz step (docs/simulation.md), while
// symplectic Euler (q' = q + h qd', the former scheme) applied every held force
// half a step early and biased them by ~10 %. The plan's feed-forward is held per
// step (first order; identical in paired runs).
//
// Real time: every buffer (delay line) is allocated in the constructor; begin_trial,
// endpoint_dynamics(_for_step), advance and the truth functions never allocate. Misuse (dt neither
// a whole multiple nor a whole fraction of step_s, unreachable start/goal) throws
// std::invalid_argument.
//
// Ground truth (paper eq. 8-18): endpoint_impedance() is the exact linearisation
// of u_ext = M_x(x) xdd - h(x, xd, t) about the current state at fixed time and fixed
// neural state (plan, delay lines, noise), i.e. Delta u = M_x Delta xdd + D Delta xd
// + K Delta x with
//   D = J^-T Dq J^-1 - M_x (H1 + Jd) J^-1
//   K = J^-T (Kq - G) J^-1 - M_x (H2 + L) J^-1 - D H1 J^-1
//   Dq = A diag(D_m) A^T + dC/dqd,  Kq = A diag(K_m) A^T + dC/dq + d(M_q qdd)/dq
//   (slack muscles excluded from diag(.)),
//   G = d(J^T)/dq u_ext, H1 = dJ/dq qd, H2 = dJ/dq qdd, L = d(Jd qd)/dq
// (xdd, u_ext at the operating point: the acceleration the plant imposed last).
// It contains the intrinsic muscle impedance and every geometric term the paper
// drops. Reflex and voluntary pathways act only through delays of >= 1 step: they
// do not respond to the *current* state, so their instantaneous impedance is zero
// and they are not part of this truth. Their effect is reported separately by
// reflex_endpoint_gains(): the endpoint stiffness/damping a pathway applies delay_p
// later. endpoint_impedance_eq16_18() is the paper's simplified version:
// J^-T A diag(D_m) A^T J^-1 and J^-T A diag(K_m) A^T J^-1 (eq. 16-18 with eq. 11).
#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "manip/common/rng.hpp"
#include "manip/common/types.hpp"
#include "manip/model/arm.hpp"
#include "manip/sim/human.hpp"

namespace manip::sim {

inline constexpr int kMuscles = 6;  // shoulder flexor, shoulder extensor, elbow flexor,
                                    // elbow extensor, biarticular flexor, biarticular extensor
using MuscleVec = Eigen::Matrix<double, kMuscles, 1>;
using MomentArms = Eigen::Matrix<double, 2, kMuscles>;  // rows: shoulder, elbow [m]

enum class Pathway : int { kShortLatency = 0, kLongLatency = 1, kVoluntary = 2 };
inline constexpr int kPathways = 3;
[[nodiscard]] const char* pathway_name(Pathway p);  // YAML key: short_latency, ...

struct FeedbackPathwayParams {
  bool enabled{false};
  double delay_s{0.0};
  double kp_npm{0.0};   // activation [N] per metre of muscle stretch error
  double kd_nspm{0.0};  // activation [N] per m/s of muscle stretch-rate error
  bool operator==(const FeedbackPathwayParams&) const = default;
};

// Every parameter of the model. The defaults equal config/arm_model.yaml, which
// cites the source of each value (a test keeps the two in step).
struct NeuromechParams {
  double step_s{1.0 / 16000.0};         // model step (manip_rt's sim backend: 4 kHz x 4 substeps)
  double session_step_s{1.0 / 4000.0};  // manip_sim's session runner: one step per 4 kHz cycle, midpoint plant
  Anthropometrics anthropometrics{};
  MomentArms moment_arms_m{(MomentArms() << 0.0536, -0.0536, 0.0, 0.0, 0.0386, -0.0388,  //
                            0.0, 0.0, 0.0316, -0.0267, 0.0427, -0.0300)
                               .finished()};
  MuscleVec k0_npm{MuscleVec::Constant(810.8)};
  MuscleVec k1_per_m{MuscleVec::Constant(75.0)};
  double stiffness_to_damping_per_s{12.0};  // D_m = K_m / this (eq. 35)
  MuscleVec tonic_activation_n{MuscleVec::Constant(26.0)};
  bool feedforward_enabled{true};
  Vec2 load_mass_kg{5.25, 5.25};     // expected M_adm + M_handle per axis (session defaults: 5 + 0.25 kg)
  Vec2 load_damping_nspm{15.0, 15.0};  // expected D_adm per axis
  std::array<FeedbackPathwayParams, kPathways> feedback{{
      {false, 0.025, 1000.0, 50.0},    // short-latency
      {true, 0.060, 2000.0, 150.0},    // long-latency = the paper's single 60 ms PD
      {false, 0.120, 2000.0, 300.0},   // voluntary
  }};
  double noise_cv{0.03};          // signal-dependent noise: std per unit activation
  double noise_floor_n{0.0};      // signal-independent part [N]
  double noise_tau_s{0.05};       // OU correlation time

  [[nodiscard]] FeedbackPathwayParams& pathway(Pathway p) { return feedback[static_cast<std::size_t>(p)]; }
  [[nodiscard]] const FeedbackPathwayParams& pathway(Pathway p) const {
    return feedback[static_cast<std::size_t>(p)];
  }
  // Empty when valid, else "<yaml key>: <reason>" for the first problem found.
  [[nodiscard]] std::optional<std::string> invalid_reason() const;
  // Intrinsic only: feedback pathways all off (the ground-truth configuration).
  void disable_feedback();
  bool operator==(const NeuromechParams& o) const;  // every field exactly equal
};

// Loads and validates a YAML file with exactly the keys of config/arm_model.yaml.
// Throws manip::ConfigError "<file>[:<line>]: <key>: <reason>" (one line; the
// common strict reader, common/yaml_reader.hpp) for a missing, unknown or
// duplicate key, a wrong type or shape, or an invalid value.
NeuromechParams load_neuromech_params(const std::string& yaml_path);
// The same keys as YAML text (no comments); load_neuromech_params reads it back.
std::string neuromech_params_to_yaml(const NeuromechParams& p);

class NeuromechanicalArm final : public HumanModel, public TruthSource {
 public:
  // Validates (std::invalid_argument "neuromech params: <key>: <reason>") and
  // allocates the delay line. The arm starts at rest at ReachSpec{}.start.
  explicit NeuromechanicalArm(const NeuromechParams& p);

  // HumanModel
  void begin_trial(const ReachSpec& reach, std::uint64_t seed) override;
  void endpoint_dynamics(Mat2& m_x_kg, Vec2& h_n) override;
  // Muscle stiffness and damping at the middle of the plant's step (see the header
  // comment "Integration"); used by step_ideal_admittance(..., midpoint = true).
  void endpoint_dynamics_for_step(double dt_s, Mat2& m_eff_kg, Vec2& h_eff_n) override;
  void advance(double dt_s, const Vec2& xdd_hand_mps2) override;
  [[nodiscard]] Vec2 hand_position_m() const override;
  [[nodiscard]] Vec2 hand_velocity_mps() const override;
  [[nodiscard]] double time_s() const override {
    return (static_cast<double>(step_) + static_cast<double>(sub_) / sub_n_) * p_.step_s;
  }

  // TruthSource: full linearisation (see the header comment).
  void endpoint_impedance(Mat2& d_nspm, Mat2& k_npm) const override;
  [[nodiscard]] std::string truth_model() const override;
  // The paper's eq. 16-18 (+ eq. 11 with the intrinsic muscle impedance only).
  void endpoint_impedance_eq16_18(Mat2& d_nspm, Mat2& k_npm) const;
  // Endpoint gains of a delayed pathway: a hand displacement/velocity now changes
  // the force on the handle by -(k dx + d dxd) one pathway delay later (geometry
  // and activation sensitivity evaluated now). Zero for a disabled pathway.
  void reflex_endpoint_gains(Pathway p, Mat2& d_nspm, Mat2& k_npm) const;

  // endpoint_dynamics at a hypothetical hand state (x, xd) at the current time with
  // the current neural state (plan, delay lines, noise): for finite differences.
  void endpoint_dynamics_at(const Vec2& x_shoulder_m, const Vec2& xd_mps, Mat2& m_x_kg, Vec2& h_n) const;

  // Joint state override (e.g. an energy test, or a backend that starts the hand
  // elsewhere). The delay lines are refilled with the new tracking error.
  void set_joint_state(const JointState& s);
  [[nodiscard]] const JointState& joint_state() const { return js_; }
  [[nodiscard]] const NeuromechParams& params() const { return p_; }
  [[nodiscard]] const TwoLinkArm& arm() const { return arm_; }
  [[nodiscard]] Vec2 last_hand_acceleration_mps2() const { return xdd_last_; }
  // Neural/muscle state at the current step (recomputed from the state, no caching).
  [[nodiscard]] MuscleVec activations_n() const;
  [[nodiscard]] MuscleVec feedforward_activations_n() const { return plan_.a_ff; }
  [[nodiscard]] MuscleVec tensions_n() const;
  [[nodiscard]] Vec2 planned_hand_position_m() const { return plan_.x; }
  [[nodiscard]] JointState planned_joint_state() const { return JointState{plan_.q, plan_.qd}; }
  // Kinetic energy of the arm segments [J].
  [[nodiscard]] double kinetic_energy_j() const { return arm_.kinetic_energy(js_.q_rad, js_.qd_radps); }

 private:
  struct Plan {  // the desired movement and its feed-forward at the current step
    Vec2 x{Vec2::Zero()}, xd{Vec2::Zero()}, xdd{Vec2::Zero()};
    Vec2 q{Vec2::Zero()}, qd{Vec2::Zero()}, qdd{Vec2::Zero()};
    MuscleVec a_ff{MuscleVec::Zero()};
  };
  struct Posture {  // trigonometry of one posture and the matrices of eq. 1 (one sincos per angle)
    double s1{0}, c1{1}, s12{0}, c12{1}, s2{0}, c2{1};
    Mat2 j{Mat2::Identity()}, jinv{Mat2::Identity()}, mq{Mat2::Identity()};
    Vec2 x{Vec2::Zero()};
  };
  struct Muscles {  // muscle quantities at one state
    MuscleVec a, k, d, tension;
    MuscleVec dtension_du;  // d tension / d drive u (activation clamp, noise gain, K1 e terms)
    MuscleVec active;  // 1 if tension > 0 (stiffness and damping act), else 0
  };

  [[nodiscard]] Posture posture(const Vec2& q) const;
  [[nodiscard]] Posture finish_posture(Posture k) const;  // j, jinv, mq, x from the sines/cosines
  // Inverse kinematics (elbow-right branch, as TwoLinkArm) without sin/cos: the
  // posture's sines and cosines follow algebraically from x. False if out of reach.
  bool posture_at_hand(const Vec2& x, Vec2& q, Posture& k) const;
  [[nodiscard]] Mat2 jacobian_dot(const Posture& k, const Vec2& qd) const;  // TwoLinkArm::jacobian_dot
  [[nodiscard]] Vec2 coriolis(const Posture& k, const Vec2& qd) const;      // TwoLinkArm::coriolis
  void set_q(const Vec2& q);                   // js_.q_rad and pose_
  void integrate(double h, const Vec2& xdd);   // mechanics over h with the hand acceleration held
  void neural_step();                          // step_ + 1: noise, plan, delay line
  void update_plan();                          // plan_ for step_
  void push_error();                           // tracking error of step_ into the delay line
  void fill_delay_line();
  [[nodiscard]] MuscleVec feedback_drive() const;
  [[nodiscard]] Muscles muscles_at(const Vec2& q, const Vec2& qd) const;
  void dynamics_at(const Posture& k, const Vec2& q, const Vec2& qd, Mat2& m_x, Vec2& h) const;
  [[nodiscard]] MuscleVec distribute(const Vec2& tau_nm);

  NeuromechParams p_;
  TwoLinkArm arm_;
  ReachSpec reach_{};
  JointState js_{};
  Posture pose_{};  // of js_.q_rad
  double m_a_{0}, m_b_{0}, m_d_{0};  // M_q = [[a + 2 b c2, d + b c2], [d + b c2, d]]
  Mat2 aat_inv_{Mat2::Identity()};   // (A A^T)^-1: muscle distribution with every muscle active
  Vec2 a_tonic_torque_{Vec2::Zero()};  // A a_tonic
  std::int64_t step_{0};
  int sub_{0}, sub_n_{1};  // plant sub-steps of the current model step done, and per model step
  Plan plan_{};
  Vec2 lambda_{Vec2::Zero()};  // warm start of the muscle-distribution solver
  Vec2 xdd_last_{Vec2::Zero()};
  std::array<int, kPathways> delay_steps_{};
  int ring_len_{1};
  std::vector<double> ring_;  // per step: q - q_d (2), qd - qd_d (2)
  MuscleVec noise_{MuscleVec::Zero()};
  double noise_rho_{0.0}, noise_sigma_{0.0};  // exact OU update coefficients per step
  PortableRng rng_{};  // nu of eq. 3: portable, so a seed reproduces the log with any standard library
};

}  // namespace manip::sim
