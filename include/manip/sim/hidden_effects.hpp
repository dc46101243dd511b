#pragma once
// "Measured" sessions with hidden mechanisms (issue 11): the simulation plus
// effects the estimator's model does not contain, written as ordinary logs.
// The session message describes the apparatus as configured, never the hidden
// effect, so a diagnosis sees only what a lab log would show.
//
// Mechanisms and what the simulation does (shoulder frame unless said):
//   delay:MAG_s     actuation delay: the perturbation force reaches the handle
//                   MAG seconds after it is commanded and logged (whole cycles;
//                   SessionDesign::actuation_delay_cycles).
//   friction:MAG_N  uncompensated stage friction, Coulomb MAG N per stage axis
//                   (workspace x and y), -MAG tanh(ẋ_axis / 1 mm/s): the tanh
//                   keeps the explicit plant step from chattering at rest.
//   handle:MAG_kg   the handle is MAG kg heavier than the session message says
//                   (the plant's handle mass is m_handle + MAG on both axes).
//   reflex:MAG      short-latency stretch reflex of MAG times the person's
//                   intrinsic stiffness (and MAG times its damping) on the
//                   deviation from the plan delayed by 30 ms (randomised in
//                   [25, 35] ms by the hidden seed).
//   feedback:MAG    feedback earlier than the model's δ_v,dev = T_est (paper
//                   §2, eq. 4-6: a long-latency reflex or an early voluntary
//                   reaction inside the window): MAG times the person's
//                   intrinsic K and D on the deviation from the plan delayed by
//                   80 ms (randomised in [60, 100] ms by the hidden seed; the
//                   paper's neuromechanical feedback delay δ_s is 60 ms, §4).
//   reflex_dir:MAG  a direction-dependent short-latency reflex: one muscle
//                   group's, along its line w and only while a deviation
//                   along w stretches it: MAG w min(0, wᵀ[K e + D ė](t − τ))
//                   with the person's intrinsic K, D (e = plan − hand), the
//                   reflex's delay, w at an angle drawn uniformly from the
//                   hidden seed (HiddenDraw::reflex_direction_rad). A
//                   push along w meets MAG × the intrinsic impedance along
//                   w more; a push against w none.
//   curl:MAG_Npm    antisymmetric (curl) stiffness [0 MAG; -MAG 0] on the
//                   deviation from the plan (heteronymous reflexes, paper §3.3).
//   sensor_lag:MAG_s     the handle force sensor's reading is its force through a
//                   first-order low pass with time constant MAG (a filtered F/T
//                   sensor: 0.5-3 ms); the admittance renders from the reading
//                   and the log records it (SessionDesign::hidden_sensor_lag_s).
//   sensor_offset:MAG_N  constant MAG N added to the reading on both workspace axes.
//   sensor_drift:MAG_N_per_s  the reading drifts by MAG N/s times the session
//                   time (cycle / sample rate) on both workspace axes (thermal
//                   drift of strain gauges: 0.01-0.1 N/s).
// The hidden seed also scales the person's D and K by one factor in
// [0.85, 1.15] and sets the session seed, so sessions differ in more than noise.
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "manip/sim/human.hpp"
#include "manip/sim/linear_human.hpp"
#include "manip/sim/session_runner.hpp"

namespace manip::sim {

enum class HiddenMechanism {
  actuation_delay,
  stage_friction,
  handle_mass,
  reflex,
  feedback,
  reflex_dir,
  curl,
  sensor_lag,
  sensor_offset,
  sensor_drift
};

struct HiddenEffect {
  HiddenMechanism mechanism{HiddenMechanism::curl};
  double magnitude{0.0};  // SI: s, N, kg, fraction of K, N/m (sensor: s, N, N/s)
};

// "delay:0.002", "friction:1", "handle:0.3", "reflex:0.5", "feedback:0.5", "reflex_dir:1", "curl:40",
// "sensor_lag:0.001", "sensor_offset:2", "sensor_drift:0.05".
// Throws manip::UsageError naming the text and what is wrong.
HiddenEffect parse_hidden_effect(const std::string& text);
[[nodiscard]] std::string to_string(HiddenMechanism m);
[[nodiscard]] std::string to_string(const HiddenEffect& e);

// What a hidden seed drew (for the study's bookkeeping: never written to the log).
struct HiddenDraw {
  std::uint64_t session_seed{1};
  double impedance_scale{1.0};   // person's D and K multiplied by this
  double reflex_delay_s{0.030};
  int actuation_delay_cycles{0};
  double feedback_delay_s{0.080};
  // reflex_dir: the displacement direction that stretches the muscle group,
  // counter-clockwise from +x1 of the shoulder frame (drawn after the others).
  double reflex_direction_rad{0.0};
};

// A person with the hidden person-side effects (reflex, feedback, curl) added to the
// force it produces. The apparatus effects (delay, friction, handle mass, force sensor) are
// in the plant (SessionDesign hooks, set by make_hidden_session), so the
// apparent truth (truth.hpp) stays the person's. Forwards the intrinsic truth
// of the person (without the hidden effects). Never allocates after
// construction.
class HiddenEffectHuman final : public HumanModel, public TruthSource {
 public:
  HiddenEffectHuman(const LinearHumanParams& person, std::vector<HiddenEffect> effects, const HiddenDraw& draw,
                    double plant_step_s);
  void begin_trial(const ReachSpec& reach, std::uint64_t seed) override;
  void endpoint_dynamics(Mat2& m_x_kg, Vec2& h_n) override;
  void advance(double dt_s, const Vec2& xdd_hand_mps2) override;
  [[nodiscard]] Vec2 hand_position_m() const override { return inner_.hand_position_m(); }
  [[nodiscard]] Vec2 hand_velocity_mps() const override { return inner_.hand_velocity_mps(); }
  [[nodiscard]] double time_s() const override { return inner_.time_s(); }
  void endpoint_impedance(Mat2& d_nspm, Mat2& k_npm) const override { inner_.endpoint_impedance(d_nspm, k_npm); }
  [[nodiscard]] std::string truth_model() const override { return inner_.truth_model(); }

 private:
  LinearImpedanceHuman inner_;
  ReachSpec reach_;
  // g [K e + D ė](t − τ) on the deviation e from the plan: the reflex, the
  // early feedback and the direction-dependent reflex, each with its own
  // delay line of (e, ė) at the plant step.
  struct DelayedCopy {
    Mat2 k_npm{Mat2::Zero()}, d_nspm{Mat2::Zero()};
    Vec2 one_sided{Vec2::Zero()};  // unit w: only w min(0, wᵀ c) of the copy c acts (zero: all of it)
    std::vector<std::array<double, 4>> ring;
    std::size_t head{0};
  };
  Mat2 curl_npm_{Mat2::Zero()};
  std::array<DelayedCopy, 3> delayed_;  // reflex, feedback, reflex_dir
};

// Builds the design and the person of one hidden session: `base` (movements,
// noise, ...) with the draw of `hidden_seed` applied.
struct HiddenSession {
  SessionDesign design;
  std::unique_ptr<HiddenEffectHuman> person;
  HiddenDraw draw;
};
HiddenSession make_hidden_session(const SessionDesign& base, const LinearHumanParams& person,
                                  const std::vector<HiddenEffect>& effects, std::uint64_t hidden_seed);

}  // namespace manip::sim
