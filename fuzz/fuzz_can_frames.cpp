// libFuzzer harness: arbitrary CAN traffic into the passive CANopen master
// (the frame decoder: SDO answers, heartbeats, EMCY, TPDOs, error frames).
// Whatever arrives, the master may fault but never crashes, never reads out of
// bounds, never overflows its preallocated transmit buffer silently and never
// throws. Input: a 13-byte record per frame (id 4, dlc 1, data 8) preceded by
// a 2-byte time step in microseconds.
// manip-fuzz-sources: src/canopen/*.cpp src/common/*.cpp
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "manip/canopen/config.hpp"
#include "manip/canopen/frame.hpp"
#include "manip/canopen/master.hpp"

namespace {
const char* kBus = R"(master:
  node_id: 127
  sync_period_us: 500
  heartbeat_ms: 20
  boot_timeout_ms: 3000
  sdo_timeout_ms: 100
  enable_timeout_ms: 500
  max_bus_load: 0.70
  tpdo_miss_limit: 2
  emcy_headroom_hz: 10
buses:
  bus_x: {interface: can0, bitrate: 1000000}
defaults:
  drive_profile: cia402_cst
  counts_per_m: 1000000
  velocity_units_per_count_s: 1
  rated_current_a: 5.0
  force_constant_n_per_a: 20.0
  max_torque_permille: 800
  heartbeat_producer_ms: 50
  heartbeat_timeout_ms: 150
  master_heartbeat_timeout_ms: 100
  abort_connection_option: 1
  vendor_id: 0xAB
  event_status_register: true
  rpdo: [controlword, target_torque]
  tpdo: [statusword, position_actual]
nodes:
  stage_x: {bus: bus_x, node_id: 1, workspace_axis: 0, sign: 1}
)";
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static manip::canopen::CanConfig cfg = [] {
    manip::canopen::CanConfig c;
    std::vector<std::string> errors;
    if (!manip::canopen::parse_config(kBus, "fuzz-bus.yml", c, errors)) std::abort();
    return c;
  }();
  manip::canopen::Master master(cfg, "bus_x");
  std::int64_t now_us = 0;
  master.start(now_us);
  manip::canopen::FrameBuffer tx;
  constexpr std::size_t kRecord = 2 + 4 + 1 + 8;
  for (std::size_t off = 0; off + kRecord <= size; off += kRecord) {
    const std::uint8_t* p = data + off;
    now_us += (p[0] | (p[1] << 8));
    manip::canopen::CanFrame f;
    std::uint32_t id = 0;
    std::memcpy(&id, p + 2, 4);
    f.id = id & 0x7FF;
    f.flags = static_cast<std::uint8_t>((id >> 29) & 0x3);  // RTR / error frames too
    f.dlc = p[6];  // may be > 8: the decoder must not trust it
    std::memcpy(f.data, p + 7, 8);
    tx.clear();
    master.process(now_us, std::span<const manip::canopen::CanFrame>(&f, 1), tx);
    if (tx.size() > manip::canopen::FrameBuffer::kCapacity) std::abort();
  }
  return 0;
}
