#pragma once
// The manipulandum as the paper's estimator assumes it: a perfectly rendered
// admittance (eq. 19-20). With the hand rigidly on the handle:
//   (M_x + M_adm + M_handle) xdd = h - D_adm xd + u_pert
// and the force sensor reads f_s = M_adm xdd + D_adm xd - u_pert (force of the
// hand side on the sensor). Shoulder frame throughout. The matrices come from
// the session description (schema::SessionDescription), the one source of
// M_adm, D_adm and the handle mass, so the simulated plant is the one the
// session message describes to the estimator.
#include <Eigen/Cholesky>

#include "manip/common/types.hpp"
#include "manip/schema/session_description.hpp"
#include "manip/sim/human.hpp"

namespace manip::sim {

// The plant of eq. 19-20 in the shoulder frame.
struct PlantParams {
  Mat2 m_adm_kg{Mat2::Zero()};
  Mat2 d_adm_nspm{Mat2::Zero()};
  Mat2 m_handle_kg{Mat2::Zero()};
};

// R diag(.) R^T of the session's per-axis values (eq. 19-20 in the shoulder frame).
inline PlantParams plant_params(const schema::SessionDescription& s) {
  return PlantParams{s.m_adm_shoulder_kg(), s.d_adm_shoulder_nspm(), s.m_handle_shoulder_kg()};
}

struct PlantSample {
  Vec2 xdd_mps2{Vec2::Zero()};
  Vec2 f_sensor_n{Vec2::Zero()};
};

// Advances human + ideal admittance by dt with the acceleration held over the step.
// explicit (default): acceleration from the state at the start of the step
// (semi-implicit Euler; the linear person of the accuracy study).
// midpoint: the human's and the admittance's damping and stiffness are taken at the
// middle of the step, linearised (HumanModel::endpoint_dynamics_for_step and
// (M + dt/2 D_adm)): second order, so a 4 kHz step is accurate (docs/simulation.md).
// The force sensor reads the admittance at the start of the step either way.
// Never allocates.
inline PlantSample step_ideal_admittance(HumanModel& human, const PlantParams& p, const Vec2& u_pert_n, double dt_s,
                                         bool midpoint = false) {
  Mat2 m_x;
  Vec2 h;
  if (midpoint)
    human.endpoint_dynamics_for_step(dt_s, m_x, h);
  else
    human.endpoint_dynamics(m_x, h);
  const Vec2 xd = human.hand_velocity_mps();
  Mat2 m = m_x + p.m_adm_kg + p.m_handle_kg;
  if (midpoint) m += (0.5 * dt_s) * p.d_adm_nspm;
  PlantSample s;
  s.xdd_mps2 = m.ldlt().solve(h - p.d_adm_nspm * xd + u_pert_n);
  s.f_sensor_n = p.m_adm_kg * s.xdd_mps2 + p.d_adm_nspm * xd - u_pert_n;
  human.advance(dt_s, s.xdd_mps2);
  return s;
}

}  // namespace manip::sim
