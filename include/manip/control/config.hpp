#pragma once
// manip_rt configuration (config/rt.yaml). Every key is required (the shipped
// file documents each value with its source or rationale), unknown keys are
// rejected, and every error names the file, the line, the key and the reason:
//   "config/rt.yaml:42: pd.kp_npm: must be > 0 (got -3)".
// The struct defaults equal the shipped file; components are unit-tested with
// them without reading a file.
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "manip/common/frames.hpp"
#include "manip/common/types.hpp"

namespace manip::control {

struct ConfigError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

enum class OverrunPolicy { kCatchUp, kReanchor };
enum class SafeLaw { kZeroForce, kDamping };

struct ParticipantConfig {
  std::string participant_id{"sim-001"};
  std::string session_id{"sim-session"};
  double body_mass_kg{0.0};   // 0 = unknown
  double body_height_m{0.0};  // 0 = unknown
  // index 0 upper arm, 1 forearm + hand (session_t)
  double segment_length_m[2]{0.31, 0.34};
  double segment_mass_kg[2]{1.93, 1.52};
  double segment_com_m[2]{0.165, 0.19};
  double segment_inertia_kgm2[2]{0.0141, 0.0188};
};

struct LoopConfig {
  double sample_rate_hz{4000.0};
  double drive_rate_hz{2000.0};
  int priority{80};
  int cpu{-1};  // -1: no affinity
  std::size_t prefault_stack_bytes{512 * 1024};
  std::size_t log_queue_capacity{65536};
  std::size_t bus_queue_capacity{4096};
  std::size_t command_queue_capacity{64};
  int max_commands_per_cycle{4};
  OverrunPolicy overrun_policy{OverrunPolicy::kCatchUp};
  int max_catch_up_cycles{4};
  int overrun_fault_consecutive{3};
  int overrun_fault_per_second{40};

  [[nodiscard]] int drive_decimation() const;  // sample_rate / drive_rate (validated integer)
  [[nodiscard]] double dt_s() const { return 1.0 / sample_rate_hz; }
};

struct AdmittanceConfig {
  Vec2 m_adm_kg{5.0, 5.0};
  Vec2 d_adm_nspm{15.0, 15.0};
};

struct PdConfig {
  Vec2 kp_npm{3.0e5, 1.0e5};
  Vec2 kd_nspm{2600.0, 880.0};
  Vec2 ff_mass_kg{12.0, 4.0};
  Vec2 ff_viscous_nspm{0.0, 0.0};
  double ff_sensor_force_gain{1.0};
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
};

struct PerturbationConfig {
  double duration_s{0.15};
  double amplitude_n{15.0};
  double trigger_x2_shoulder_m{0.40};
  std::vector<double> angles_deg{30, 60, 120, 150, 210, 240, 300, 330};
  int repeats_per_angle{3};
  [[nodiscard]] int full_set() const { return static_cast<int>(angles_deg.size()) * repeats_per_angle; }
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
};

struct LoggerConfig {
  double flush_interval_s{0.5};
};

struct BusConfig {
  std::string lcm_url{"udpm://239.255.76.67:7667?ttl=0"};
  double state_rate_hz{250.0};
  double health_rate_hz{1.0};
  int subscription_queue_capacity{1000};
};

struct SimHumanConfig {
  std::string model{"linear"};                        // linear | neuromech
  std::string arm_config{"config/arm_model.yaml"};    // neuromech parameters (relative to the working directory)
  Mat2 m_kg{(Mat2() << 1.515460, -0.824986, -0.824986, 1.409055).finished()};
  Mat2 d_nspm{(Mat2() << 10.98, -7.94, -8.54, 6.75).finished()};
  Mat2 k_npm{(Mat2() << 110.52, -106.05, -106.05, 313.75).finished()};
  Mat2 m_load_kg{Mat2::Identity() * 5.25};
  Mat2 d_load_nspm{Mat2::Identity() * 15.0};
  double voluntary_delay_s{0.160};
  Mat2 k_voluntary_npm{Mat2::Identity() * 300.0};
  Mat2 d_voluntary_nspm{Mat2::Identity() * 30.0};
  double motor_noise_n{0.0};
  double motor_noise_tau_s{0.05};
};

struct SimParticipantConfig {
  double reaction_time_s{0.25};
  double reaction_time_jitter_s{0.05};
  double reach_duration_s{3.0};
  double reach_duration_jitter_s{0.25};
  double return_duration_s{1.2};
  double lateral_bow_std_m{0.003};
};

struct SimConfig {
  Vec2 stage_mass_kg{12.0, 4.0};
  Vec2 viscous_nspm{20.0, 10.0};
  Vec2 coulomb_n{4.0, 2.0};
  double coulomb_velocity_mps{0.001};
  double encoder_resolution_m{1e-6};
  double force_noise_n{0.0};
  double drive_peak_force_n{400.0};
  int substeps{4};
  std::uint64_t seed{1};
  SimHumanConfig human{};
  SimParticipantConfig participant{};
};

struct RtConfig {
  ParticipantConfig participant{};
  WorkspaceToShoulder frames{};
  LoopConfig loop{};
  AdmittanceConfig admittance{};
  Vec2 handle_mass_kg{0.25, 0.25};
  PdConfig pd{};
  SafetyConfig safety{};
  PerturbationConfig perturbation{};
  ProtocolConfig protocol{};
  LoggerConfig logger{};
  BusConfig bus{};
  SimConfig sim{};

  std::string source_name;     // file the config came from ("" for built-in defaults)
  std::string effective_yaml;  // complete effective configuration text (session_t.config_yaml)

  [[nodiscard]] int perturbed_count() const {
    return protocol.perturbed_trials < 0 ? perturbation.full_set() : protocol.perturbed_trials;
  }
};

// key path ("protocol.movements") -> YAML scalar text ("12")
using ConfigOverrides = std::vector<std::pair<std::string, std::string>>;

// Parse and validate. `name` is used in messages (normally the path). With
// overrides, the effective text is the re-emitted YAML (comments dropped) with
// a header naming the source and the overrides; without, the original text.
RtConfig parse_rt_config(const std::string& yaml_text, const std::string& name, const ConfigOverrides& overrides = {});
// Reads the file; ConfigError if it cannot be read or is invalid.
RtConfig load_rt_config(const std::string& path, const ConfigOverrides& overrides = {});

// Overrides that shorten a session to n movements keeping the perturbed
// fraction of the configured design (round(n * perturbed / movements)).
ConfigOverrides trials_overrides(const RtConfig& cfg, int n_movements);

}  // namespace manip::control
