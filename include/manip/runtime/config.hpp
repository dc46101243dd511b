#pragma once
// manip_rt configuration (config/rt.yaml). Every key is required (the shipped
// file documents each value with its source or rationale), unknown and
// duplicate keys are rejected, and every error names the file, the line, the
// key and the reason, thrown as manip::ConfigError (exit code 3):
//   "config/rt.yaml:42: pd.kp_npm: must be > 0 (got -3)".
// The built-in defaults (RtConfig{}) equal the shipped file field for field
// (tests/runtime/test_config.cpp compares every field), so components are
// unit-tested with them without reading a file.
//
// rt.yaml section -> field:
//   participant, frames, admittance, handle, loop.sample/drive_rate_hz,
//   perturbation.duration_s/amplitude_n/trigger_x2_shoulder_m -> session
//   (the one schema::SessionDescription, sent as session_t);
//   pd, safety, perturbation.angles/repeats, protocol, loop.max_commands_per_cycle,
//   loop.overrun_fault_*, bus.state_rate_hz -> the control law's ControlConfig;
//   the rest of loop, logger, bus -> the runtime; sim -> the sim backend.
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "manip/common/errors.hpp"
#include "manip/control/config.hpp"
#include "manip/hardware/sim_backend_config.hpp"

namespace manip::runtime {

enum class OverrunPolicy { kCatchUp, kReanchor };

// The 4 kHz thread and its queues (rt.yaml `loop:`, minus what the law reads).
struct LoopConfig {
  int priority{80};
  int cpu{-1};  // -1: no affinity
  std::size_t prefault_stack_bytes{512 * 1024};
  std::size_t log_queue_capacity{65536};
  std::size_t bus_queue_capacity{4096};
  std::size_t command_queue_capacity{64};
  OverrunPolicy overrun_policy{OverrunPolicy::kCatchUp};
  int max_catch_up_cycles{4};
  bool operator==(const LoopConfig&) const = default;
};

struct LoggerConfig {
  double flush_interval_s{0.5};
  // Also flush every this many cycles (optional key; an as-fast-as-possible
  // run makes many cycles per wall-clock second): a kill -9 loses at most
  // this many cycles plus the log queue's content.
  long long flush_every_cycles{4000};
  bool operator==(const LoggerConfig&) const = default;
};

struct BusConfig {
  std::string lcm_url{"udpm://239.255.76.67:7667?ttl=0"};
  double health_rate_hz{1.0};
  int subscription_queue_capacity{1000};
  bool operator==(const BusConfig&) const = default;
};

// The session the shipped rt.yaml describes (ids of the simulated participant;
// everything else is SessionDescription's defaults, which rt.yaml repeats).
schema::SessionDescription default_session();

struct RtConfig : control::ControlConfig {
  RtConfig() { session = default_session(); }

  LoopConfig loop{};
  LoggerConfig logger{};
  BusConfig bus{};
  hardware::SimConfig sim{};

  std::string source_name;     // file the config came from ("" for built-in defaults)
  std::string effective_yaml;  // complete effective configuration text (session_t.config_yaml)
};

// Field-complete comparison of everything rt.yaml sets (the session's
// run-time fields software_version/source/utime_start/config_yaml and
// source_name/effective_yaml are not configuration and are not compared).
// Returns "" when equal, else the first differing key path.
std::string first_difference(const RtConfig& a, const RtConfig& b);

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

}  // namespace manip::runtime
