#pragma once
// A simulated person holding the handle. The hand is rigidly attached to the
// handle, so the plant the person is coupled to (ideal admittance, or the
// stages of the controller's sim backend) solves for the common acceleration:
//
//   human:  M_x(t) xdd = h(t) + u_ext          (endpoint form of eq. 1 + 2)
//   plant:  u_ext = force the handle applies on the hand
//
// e.g. on the ideal admittance (eq. 19-20): (M_x + M_adm + M_handle) xdd =
// h - D_adm xd + u_pert. Everything is in the *shoulder* frame.
// Implementations must not allocate in endpoint_dynamics/advance (they run
// inside the 4 kHz loop of manip_rt's sim backend); begin_trial may not
// allocate either once constructed.
#include <cstdint>
#include <string>

#include "manip/common/types.hpp"

namespace manip::sim {

// One reach the person intends to make.
struct ReachSpec {
  Vec2 start_shoulder_m{0.0, 0.30};
  Vec2 goal_shoulder_m{0.0, 0.55};
  double t_start_s{0.5};    // movement onset, seconds after begin_trial
  double duration_s{3.0};   // minimum-jerk duration
  double lateral_bow_m{0};  // path variation: peak lateral deviation of the plan
};

class HumanModel {
 public:
  virtual ~HumanModel() = default;
  // Put the hand at rest at reach.start_shoulder_m with time 0 and plan the reach.
  // The seed fixes every random process of this trial (paired runs reuse it).
  virtual void begin_trial(const ReachSpec& reach, std::uint64_t seed) = 0;
  // Endpoint inertia M_x [kg] and the endpoint force h [N] the arm produces at
  // the current state (muscles, feedback, noise, minus velocity-product terms).
  virtual void endpoint_dynamics(Mat2& m_x_kg, Vec2& h_n) = 0;
  // The same for a plant step of dt_s whose acceleration is held over the step: a
  // model may return an effective inertia and force that treat its own damping and
  // stiffness at the middle of the step (linearly implicit), so that the step is
  // second-order accurate. Default: endpoint_dynamics (explicit).
  virtual void endpoint_dynamics_for_step(double dt_s, Mat2& m_eff_kg, Vec2& h_eff_n) {
    (void)dt_s;
    endpoint_dynamics(m_eff_kg, h_eff_n);
  }
  // Advance time by dt with the endpoint acceleration imposed by the plant.
  virtual void advance(double dt_s, const Vec2& xdd_hand_mps2) = 0;
  [[nodiscard]] virtual Vec2 hand_position_m() const = 0;
  [[nodiscard]] virtual Vec2 hand_velocity_mps() const = 0;
  [[nodiscard]] virtual double time_s() const = 0;
};

// Optional for a HumanModel: the endpoint impedance about its current state,
// used as ground truth by the session runner (averaged over [0, T_est] of the
// unperturbed twin).
class TruthSource {
 public:
  virtual ~TruthSource() = default;
  virtual void endpoint_impedance(Mat2& d_nspm, Mat2& k_npm) const = 0;
  [[nodiscard]] virtual std::string truth_model() const = 0;
};

}  // namespace manip::sim
