#pragma once
// Parameters of the control law (the 4 kHz loop body): plain data, no I/O.
// The session constants (sample and drive rate, M_adm and D_adm of eq. 20,
// handle mass of eq. 19, frame offset, perturbation design of eq. 22-23) come
// from the one schema::SessionDescription; everything else here is the law's
// own tuning. runtime::load_rt_config fills these from config/rt.yaml; the
// built-in defaults equal the shipped file (tests/runtime/test_config.cpp
// compares every field).
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "manip/common/types.hpp"
#include "manip/schema/session_description.hpp"

namespace manip::control {

enum class SafeLaw { kZeroForce, kDamping };

// Per-cycle budgets of the loop body and the overrun fault (rt.yaml `loop:`),
// and the decimation of live states (rt.yaml `bus.state_rate_hz`).
struct CycleConfig {
  int max_commands_per_cycle{4};
  int overrun_fault_consecutive{3};
  int overrun_fault_per_second{40};
  double live_state_rate_hz{250.0};
  bool operator==(const CycleConfig&) const = default;
};

struct PdConfig {
  Vec2 kp_npm{3.0e5, 1.0e5};
  Vec2 kd_nspm{2600.0, 880.0};
  Vec2 ff_mass_kg{12.0, 4.0};
  Vec2 ff_viscous_nspm{0.0, 0.0};
  double ff_sensor_force_gain{1.0};
  bool operator==(const PdConfig&) const = default;
};

struct SafetyConfig {
  double workspace_limit_m{0.147};
  double wall_start_m{0.135};
  double wall_stiffness_npm{5000.0};
  double wall_damping_nspm{100.0};
  double max_velocity_mps{1.0};
  double max_handle_force_n{60.0};
  double sensor_saturation_n{100.0};
  double max_motor_force_n{200.0};
  double max_pert_amplitude_n{30.0};
  double max_tracking_error_m{0.01};
  int stale_cycles{4};
  SafeLaw safe_law{SafeLaw::kDamping};
  double safe_damping_nspm{30.0};
  int fault_history_cycles{400};
  int shutdown_cycles{40};
  bool operator==(const SafetyConfig&) const = default;
};

// The schedule part of the perturbation (paper §4.2, §5.2); the pulse itself
// (T_pert, A_pert, trigger line) is session.perturbation.
struct PerturbationConfig {
  std::vector<double> angles_deg{30, 60, 120, 150, 210, 240, 300, 330};
  int repeats_per_angle{3};
  [[nodiscard]] int full_set() const { return static_cast<int>(angles_deg.size()) * repeats_per_angle; }
  bool operator==(const PerturbationConfig&) const = default;
};

struct ProtocolConfig {
  int movements{100};
  int perturbed_trials{-1};  // -1: angles x repeats; fewer: first k of the shuffled set
  std::uint64_t seed{20261123};
  bool autostart{true};
  Vec2 start_shoulder_m{0.0, 0.30};
  Vec2 goal_shoulder_m{0.0, 0.55};
  double target_radius_m{0.01};
  double rest_speed_mps{0.01};
  double start_hold_s{0.5};
  double goal_hold_s{0.3};
  double trial_timeout_s{8.0};
  int max_requeues{3};
  bool operator==(const ProtocolConfig&) const = default;
};

struct ControlConfig {
  schema::SessionDescription session{};
  CycleConfig cycle{};
  PdConfig pd{};
  SafetyConfig safety{};
  PerturbationConfig perturbation{};
  ProtocolConfig protocol{};

  [[nodiscard]] double dt_s() const { return 1.0 / session.sample_rate_hz; }
  // sample_rate / drive_rate (validated to be a whole number by the loader).
  [[nodiscard]] int drive_decimation() const {
    return static_cast<int>(std::lround(session.sample_rate_hz / session.drive_rate_hz));
  }
  [[nodiscard]] int perturbed_count() const {
    return protocol.perturbed_trials < 0 ? perturbation.full_set() : protocol.perturbed_trials;
  }
};

}  // namespace manip::control
