#pragma once
// Simulation backend: the two stages as masses with viscous + Coulomb friction,
// driven by the motor force the controller sends (held between drive ticks:
// zero-order hold at the drive rate), with a simulated person rigidly holding
// the handle (any sim::HumanModel: the linear-impedance arm or the
// neuromechanical two-link arm, selected by sim.human.model).
//
// Plant (workspace axes; R = workspace->shoulder rotation; m_s stage moving
// mass per axis (axis 1 carries axis 2), m_h handle mass above the sensor):
//   stage+handle: (m_s + m_h) xdd = F_motor - b xd - Fc tanh(xd / v_c) + f_h
//   hand:         M_x xdd_sh = h + u_ext,  u_ext = -R f_h (handle on hand)
//   => (diag(m_s + m_h) + R^T M_x R) xdd = F_motor - friction + R^T h
//   sensor:       f_s = f_h - m_h xdd   (force of the hand side on the sensor)
// Integrated with `substeps` semi-implicit Euler steps per control cycle (the
// human integrates its own state with the imposed acceleration). Readings:
// encoder positions quantised to encoder_resolution_m, the drive's velocity
// estimate (exact here), the sensor force (+ optional white noise).
//
// The simulated participant watches the display cue like a real one watches
// the screen: when a trial starts it reaches to the goal after a reaction time
// (minimum-jerk plan of reach_duration +- jitter, lateral bow ~ N(0, std));
// when the trial ends it returns to the start target. Every plan calls
// HumanModel::begin_trial from the current hand position (at rest: the
// controller only changes phase when the handle rests in a target).
// Deterministic for a given sim.seed. Never allocates after construction.
#include <memory>

#include "manip/common/frames.hpp"
#include "manip/common/rng.hpp"
#include "manip/control/config.hpp"
#include "manip/hardware/backend.hpp"
#include "manip/hardware/sim_backend_config.hpp"
#include "manip/sim/human.hpp"

namespace manip::hardware {

// The simulated person selected by sim.human (sample rate = loop rate x
// substeps). The only place the sim backend builds a human model: switch it to
// sim's human factory here. Throws ConfigError on bad parameters.
std::unique_ptr<sim::HumanModel> make_sim_human(const control::ControlConfig& law, const SimConfig& sim);

class SimBackend final : public Backend {
 public:
  // law: the session (rates, frame, handle mass) and the start target where the
  // simulated participant waits; sim: rt.yaml's `sim:` section.
  SimBackend(const control::ControlConfig& law, const SimConfig& sim, std::unique_ptr<sim::HumanModel> human);

  [[nodiscard]] std::string name() const override { return "sim"; }
  [[nodiscard]] bool supports_as_fast_as_possible() const override { return true; }
  void read(control::SensorReading& out) override;
  void write(const control::ActuatorCommand& cmd) override;
  void display(const control::DisplayCue& cue) override;

  // Fault injection for tests (applied from the next read).
  struct Injection {
    bool nan_force{false};
    bool stale{false};
    bool hw_estop{false};
    bool drive_fault{false};
    Vec2 force_offset_n{Vec2::Zero()};  // added to the sensor reading
    Vec2 external_force_n{Vec2::Zero()};  // extra force on the stages (e.g. a collision), workspace
  };
  Injection inject{};

  [[nodiscard]] sim::HumanModel& human() { return *human_; }
  [[nodiscard]] double time_s() const { return t_; }
  [[nodiscard]] Vec2 applied_force_n() const { return f_applied_; }
  [[nodiscard]] Vec2 true_position_workspace_m() const;
  [[nodiscard]] Vec2 true_velocity_workspace_mps() const;
  [[nodiscard]] Vec2 true_sensor_force_n() const { return f_sensor_; }
  [[nodiscard]] int plans() const { return plans_; }
  [[nodiscard]] bool enabled() const { return enabled_; }

 private:
  void on_configure() override;
  void on_enable() override {}
  void on_disable() noexcept override;
  void physics_step(double dt);
  void plan(const Vec2& to_sh, double duration_s);

  Vec2 start_target_shoulder_m_;
  Vec2 m_handle_kg_;
  SimConfig sim_;
  std::unique_ptr<sim::HumanModel> human_;
  WorkspaceToShoulder frame_;
  Mat2 rot_;
  double dt_;
  int substeps_;
  Vec2 m_stage_handle_;
  PortableRng rng_;
  PortableRng noise_rng_;
  bool started_{false};
  bool first_read_{true};
  bool enabled_{false};
  Vec2 f_cmd_{Vec2::Zero()};
  Vec2 f_applied_{Vec2::Zero()};
  Vec2 f_sensor_{Vec2::Zero()};
  double t_{0.0};
  std::uint64_t seq_{0};
  // participant
  std::int32_t planned_trial_{-1};
  bool heading_to_goal_{false};
  Vec2 planned_target_{Vec2::Zero()};
  int plans_{0};
};

}  // namespace manip::hardware
