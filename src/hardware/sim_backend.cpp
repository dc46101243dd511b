#include "manip/hardware/sim_backend.hpp"

#include <Eigen/LU>

#include <cmath>

#include "manip/sim/human_factory.hpp"

namespace manip::hardware {

std::unique_ptr<sim::HumanModel> make_sim_human(const control::ControlConfig& law, const SimConfig& sim) {
  // The one human-model factory (sim/human_factory.hpp), at the backend's plant
  // step: it refuses a substep the model cannot integrate (a neuromech arm whose
  // integration step does not divide 1/(f_s substeps)) at start-up.
  const auto& h = sim.human;
  sim::HumanSpec spec;
  spec.model = h.model;
  spec.sample_rate_hz = law.session.sample_rate_hz;
  spec.plant_step_s = 1.0 / (law.session.sample_rate_hz * sim.substeps);
  spec.arm_config = h.arm_config;
  spec.linear.m_kg = h.m_kg;
  spec.linear.d_nspm = h.d_nspm;
  spec.linear.k_npm = h.k_npm;
  spec.linear.m_load_kg = h.m_load_kg;
  spec.linear.d_load_nspm = h.d_load_nspm;
  spec.linear.voluntary_delay_s = h.voluntary_delay_s;
  spec.linear.k_voluntary_npm = h.k_voluntary_npm;
  spec.linear.d_voluntary_nspm = h.d_voluntary_nspm;
  spec.linear.motor_noise_n = h.motor_noise_n;
  spec.linear.motor_noise_tau_s = h.motor_noise_tau_s;
  return sim::make_human(spec).model;
}

SimBackend::SimBackend(const control::ControlConfig& law, const SimConfig& sim,
                       std::unique_ptr<sim::HumanModel> human)
    : start_target_shoulder_m_(law.protocol.start_shoulder_m),
      m_handle_kg_(law.session.m_handle_kg),
      sim_(sim),
      human_(std::move(human)),
      frame_(law.session.frame),
      rot_(law.session.frame.rotation()),
      dt_(law.dt_s()),
      substeps_(sim.substeps),
      m_stage_handle_(sim.stage_mass_kg + law.session.m_handle_kg),
      rng_(sim.seed),
      noise_rng_(sim.seed ^ 0xF0E1D2C3B4A59687ULL) {}

void SimBackend::on_configure() {
  // The participant starts at rest in the start target, holding still.
  sim::ReachSpec hold;
  hold.start_shoulder_m = start_target_shoulder_m_;
  hold.goal_shoulder_m = start_target_shoulder_m_;
  hold.t_start_s = 0.0;
  hold.duration_s = 1.0;
  hold.lateral_bow_m = 0.0;
  human_->begin_trial(hold, rng_.next());
  planned_target_ = start_target_shoulder_m_;
  heading_to_goal_ = false;
  planned_trial_ = -1;
  started_ = true;
  first_read_ = true;
  enabled_ = false;
  f_cmd_.setZero();
  t_ = 0.0;
}

void SimBackend::on_disable() noexcept {
  enabled_ = false;
  f_cmd_.setZero();
  f_applied_.setZero();
}

Vec2 SimBackend::true_position_workspace_m() const { return frame_.point_to_workspace(human_->hand_position_m()); }
Vec2 SimBackend::true_velocity_workspace_mps() const {
  return frame_.vector_to_workspace(human_->hand_velocity_mps());
}

void SimBackend::plan(const Vec2& to_sh, double duration_s) {
  const auto& p = sim_.participant;
  sim::ReachSpec r;
  r.start_shoulder_m = human_->hand_position_m();
  r.goal_shoulder_m = to_sh;
  r.t_start_s = p.reaction_time_s + p.reaction_time_jitter_s * (2.0 * rng_.uniform() - 1.0);
  r.duration_s = duration_s;
  r.lateral_bow_m = p.lateral_bow_std_m * rng_.normal();
  human_->begin_trial(r, rng_.next());
  planned_target_ = to_sh;
  ++plans_;
}

void SimBackend::display(const control::DisplayCue& cue) {
  using control::Phase;
  const auto& p = sim_.participant;
  if (cue.trial >= 0 && cue.trial != planned_trial_ && cue.phase == Phase::kReach) {
    planned_trial_ = cue.trial;
    heading_to_goal_ = true;
    plan(cue.goal_shoulder_m, p.reach_duration_s + p.reach_duration_jitter_s * (2.0 * rng_.uniform() - 1.0));
  } else if ((cue.phase == Phase::kReturn || cue.phase == Phase::kWaiting) &&
             (heading_to_goal_ || (cue.start_shoulder_m - planned_target_).norm() > 1e-9)) {
    heading_to_goal_ = false;
    plan(cue.start_shoulder_m, p.return_duration_s);
  }
}

void SimBackend::write(const control::ActuatorCommand& cmd) {
  enabled_ = cmd.enable;
  f_cmd_ = cmd.f_motor_n;
}

void SimBackend::physics_step(double dt) {
  const auto& s = sim_;
  Mat2 m_x;
  Vec2 h;
  human_->endpoint_dynamics(m_x, h);
  const Vec2 xd_w = rot_.transpose() * human_->hand_velocity_mps();
  Vec2 fric;
  for (int i = 0; i < 2; ++i)
    fric[i] = s.viscous_nspm[i] * xd_w[i] + s.coulomb_n[i] * std::tanh(xd_w[i] / s.coulomb_velocity_mps);
  for (int i = 0; i < 2; ++i) {
    const double f = enabled_ ? f_cmd_[i] : 0.0;
    f_applied_[i] = std::isfinite(f) ? std::clamp(f, -s.drive_peak_force_n, s.drive_peak_force_n) : 0.0;
  }
  Mat2 m_tot = rot_.transpose() * m_x * rot_;
  m_tot(0, 0) += m_stage_handle_[0];
  m_tot(1, 1) += m_stage_handle_[1];
  const Vec2 rhs = f_applied_ - fric + inject.external_force_n + rot_.transpose() * h;
  const Vec2 xdd_w = m_tot.inverse() * rhs;  // 2x2: closed-form inverse, no allocation
  const Vec2 xdd_sh = rot_ * xdd_w;
  const Vec2 u_ext_sh = m_x * xdd_sh - h;            // force of the handle on the hand
  const Vec2 f_h_w = -(rot_.transpose() * u_ext_sh);  // force of the hand on the handle
  f_sensor_ = f_h_w - m_handle_kg_.cwiseProduct(xdd_w);
  human_->advance(dt, xdd_sh);
  t_ += dt;
}

void SimBackend::read(control::SensorReading& out) {
  if (!first_read_) {
    const double h = dt_ / substeps_;
    for (int i = 0; i < substeps_; ++i) physics_step(h);
  }
  first_read_ = false;
  const Vec2 x = true_position_workspace_m();
  const double res = sim_.encoder_resolution_m;
  for (int i = 0; i < 2; ++i) out.x_workspace_m[i] = res > 0 ? std::round(x[i] / res) * res : x[i];
  out.xd_workspace_mps = true_velocity_workspace_mps();
  Vec2 f = f_sensor_ + inject.force_offset_n;
  if (sim_.force_noise_n > 0)
    f += sim_.force_noise_n * Vec2(noise_rng_.normal(), noise_rng_.normal());
  if (inject.nan_force) f[0] = std::nan("");
  out.f_sensor_workspace_n = f;
  if (!inject.stale) ++seq_;
  out.position_seq = seq_;
  out.force_seq = seq_;
  out.status = 0;
  if (enabled_) out.status |= control::backend_status::kDrivesEnabled;
  if (inject.hw_estop) out.status |= control::backend_status::kHwEStopOpen;
  if (inject.drive_fault) out.status |= control::backend_status::kDriveFault;
}

}  // namespace manip::hardware
