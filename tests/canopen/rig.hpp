#pragma once
// Shared test set-ups: YAML configurations (also exercise the reader).
#include <catch2/catch.hpp>

#include <string>

#include "manip/canopen/can_check.hpp"
#include "manip/canopen/config.hpp"

namespace canopen_test {

// One bus per drive, SYNC 500 us (2 kHz). Axis 1 is driven by node 1 on
// can1 with a negative sign to exercise the axis mapping.
inline const char* kTwoBuses = R"(master:
  node_id: 127
  sync_period_us: 500
  heartbeat_ms: 20
  boot_timeout_ms: 200
  sdo_timeout_ms: 20
  enable_timeout_ms: 100
  tpdo_miss_limit: 3
buses:
  bus_x: {interface: can0, bitrate: 1000000}
  bus_y: {interface: can1, bitrate: 1000000}
defaults:
  counts_per_m: 1000000
  rated_current_a: 5.0
  force_constant_n_per_a: 20.0
  heartbeat_producer_ms: 50
  heartbeat_timeout_ms: 150
  master_heartbeat_timeout_ms: 100
  vendor_id: 0xAB
  event_status_register: true
nodes:
  stage_x:
    bus: bus_x
    node_id: 1
    workspace_axis: 0
    sign: 1
  stage_y:
    bus: bus_y
    node_id: 1
    workspace_axis: 1
    sign: -1
)";

// Shared bus, both drives, SYNC 1 ms (2 kHz does not fit: 95.9 %).
inline const char* kSharedBus = R"(master:
  sync_period_us: 1000
  boot_timeout_ms: 200
  sdo_timeout_ms: 20
  enable_timeout_ms: 100
buses:
  can: {interface: can0}
defaults:
  bus: can
  counts_per_m: 1000000
  rated_current_a: 5.0
  force_constant_n_per_a: 20.0
nodes:
  stage_x: {node_id: 1, workspace_axis: 0}
  stage_y: {node_id: 2, workspace_axis: 1}
)";

inline manip::canopen::CanConfig parse_ok(const std::string& text) {
  manip::canopen::CanConfig c;
  std::vector<std::string> errors;
  const bool ok = manip::canopen::parse_config(text, "test.yml", c, errors);
  INFO((errors.empty() ? std::string() : errors.front()));
  REQUIRE(ok);
  return c;
}

}  // namespace canopen_test
