#pragma once
// CANopen bus configuration (YAML in the style of ros2_canopen's bus.yml),
// strictly validated: unknown keys and wrong types are rejected with
// "file:line: key: reason". Parser in src/canopen/config.cpp only.
#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace manip::canopen {

// Objects manip maps into PDOs (CiA 402-2 object numbers).
// DigitalInputs: CiA 402 0x60FD (32 bits; bits 0-3 limit/home/interlock,
// 16-31 manufacturer-specific, e.g. the input wired to the e-stop chain).
enum class PdoObject : uint8_t { Controlword, TargetTorque, Statusword, PositionActual, VelocityActual, DigitalInputs };
struct ObjectRef {
  uint16_t index;
  uint8_t sub;
  uint8_t bits;
};
ObjectRef object_ref(PdoObject o);
const char* to_string(PdoObject o);
// CiA 301 §7.4.8.2 mapping entry: index<<16 | sub<<8 | length in bits.
inline uint32_t mapping_entry(ObjectRef r) {
  return (uint32_t(r.index) << 16) | (uint32_t(r.sub) << 8) | r.bits;
}

struct PdoMapping {
  std::array<PdoObject, 8> objects{};
  uint8_t count = 0;
  int bytes() const;
  bool contains(PdoObject o) const;
  void add(PdoObject o) { if (count < objects.size()) objects[count++] = o; }
};

struct MasterConfig {
  uint8_t node_id = 127;              // the master's own heartbeat COB-ID 0x700+node_id
  uint32_t sync_period_us = 500;      // SYNC producer period (drive command rate 2 kHz)
  uint32_t heartbeat_ms = 20;         // master heartbeat producer (drives consume it, 0x1016)
  uint32_t boot_timeout_ms = 3000;    // deadline for each node's boot-up after NMT reset
  uint32_t sdo_timeout_ms = 100;
  uint32_t enable_timeout_ms = 500;   // CiA 402 to Operation enabled
  uint32_t fault_reset_timeout_ms = 20;  // a drive still in Fault this long after the reset edge: reset failed
  double max_bus_load = 0.70;         // refuse to start above this worst-case load
  uint32_t tpdo_miss_limit = 2;       // consecutive SYNC periods without TPDO -> fault
  double emcy_headroom_hz = 10.0;     // reserved EMCY frames per node and second in the budget
};

struct BusConfig {
  std::string name;
  std::string interface;        // e.g. can0
  uint32_t bitrate = 1000000;   // bit/s
};

struct DriveConfig {
  std::string name;
  std::string bus;                       // BusConfig::name
  uint8_t node_id = 0;
  int workspace_axis = 0;                // 0 -> workspace x1, 1 -> x2
  int sign = 1;                          // +1/-1: drive positive direction vs workspace axis
  double counts_per_m = 0;               // encoder counts per metre of stage travel
  double velocity_units_per_count_s = 1; // 0x606C units per (count/s) (Copley: 10, i.e. 0.1 count/s)
  double rated_current_a = 0;            // 0x6075 motor rated current: 1000 per mille of torque
  double force_constant_n_per_a = 0;     // linear motor force constant
  uint32_t max_torque_permille = 1000;   // command saturation
  uint32_t heartbeat_producer_ms = 50;   // written to 0x1017
  uint32_t heartbeat_timeout_ms = 150;   // how long the master waits for this node's heartbeat
  uint32_t master_heartbeat_timeout_ms = 100;  // written to 0x1016:01 (drive consumes master)
  int16_t abort_connection_option = 1;   // 0x6007: 1 = fault on heartbeat/comm loss
  uint32_t vendor_id = 0;                // expected 0x1018:01 (0 = not checked)
  uint32_t product_code = 0;             // expected 0x1018:02 (0 = not checked)
  bool event_status_register = false;   // Copley: read 0x1002 after a fault
  PdoMapping rpdo;                       // RPDO1
  PdoMapping tpdo;                       // TPDO1
  PdoMapping tpdo2;                      // TPDO2 (optional, count 0 = disabled)

  double rated_force_n() const { return rated_current_a * force_constant_n_per_a; }
};

// The `backend:` section: what the `can` hardware backend of manip_rt adds
// around the drives (safety inputs, force sensor, in-process simulation).
struct BackendOptions {
  bool virtual_bus = false;           // run simulated drives in-process (VirtualBus), no SocketCAN
  // Safety inputs read from each drive's statusword every cycle (docs/hardware.md):
  // the e-stop chain / STO status on a manufacturer-specific 0x6041 bit
  // (8, 14 or 15; -1 = not wired) and its level when the chain is open.
  int estop_statusword_bit = -1;
  bool estop_active_high = true;
  // The e-stop chain / STO input read through CiA 402 0x60FD "digital
  // inputs", mapped into tpdo or tpdo2 of every drive (-1 = not used): the
  // bit (0..31) wired to the chain and the level that means "open".
  int estop_input_bit = -1;
  bool estop_input_open_high = false;  // default: the chain holds the input high while closed
  // CiA 402 0x6041 bit 4 "voltage enabled" dropping while Operation enabled
  // means the power stage lost its supply (STO / contactor of the e-stop chain).
  bool estop_on_voltage_loss = true;
  // Force sensor boundary.
  std::string force_sensor = "sim";   // sim | netft | jr3 | none (virtual_bus always uses the simulated sensor)
  bool tare = true;                   // bias at session start (enable), hand resting on the handle
  uint32_t tare_samples = 200;        // averaged samples for the bias
  double force_full_scale_n = 200.0;  // sensor full scale per axis: |F| at or above -> saturated
  uint32_t force_stale_cycles = 20;   // control cycles without a new sample -> stale (comm error)
  double sensor_rotation_deg = 0.0;   // sensor x axis -> workspace x1, counter-clockwise
  std::string netft_address = "192.168.1.1";
  uint32_t netft_port = 49152;        // ATI RDT UDP port
  double netft_counts_per_force = 1000000.0;  // Net F/T "counts per force" (its web page / calibration)
  std::string jr3_device = "/dev/jr3";  // jr3pci driver character device
  int jr3_filter = 1;                   // JR3 DSP filter 0..6 (0 = raw)
  // Raw CAN traffic into the session log (channel MANIP_CAN_RAW, can_frames_t):
  // every frame sent and received, through a preallocated lock-free queue of
  // raw_queue_frames frames the logger thread drains; overflow is counted.
  bool record_raw_frames = false;
  uint32_t raw_queue_frames = 65536;
};

struct CanConfig {
  MasterConfig master;
  BackendOptions backend;
  std::vector<BusConfig> buses;
  std::vector<DriveConfig> drives;
  std::string source = "<string>";
};

// Parse and validate. On failure returns false and fills `errors` with
// "file:line: key: reason" lines (every problem found, not only the first).
bool parse_config(const std::string& yaml_text, const std::string& source_name, CanConfig& out,
                  std::vector<std::string>& errors);
bool load_config(const std::string& path, CanConfig& out, std::vector<std::string>& errors);

// Unit conversions (the one place): encoder counts <-> metres, torque per
// mille <-> newtons, drive axis <-> workspace axis with sign.
struct AxisScaling {
  double counts_per_m = 1;
  double velocity_units_per_count_s = 1;
  double rated_force_n = 1;
  double max_torque_permille = 1000;
  int sign = 1;
  int workspace_axis = 0;

  static AxisScaling from(const DriveConfig& d);
  double position_m(int32_t counts) const { return sign * double(counts) / counts_per_m; }
  double velocity_mps(int32_t units) const {
    return sign * double(units) / velocity_units_per_count_s / counts_per_m;
  }
  // Workspace force along this axis -> 0x6071 target torque (per mille of rated), saturated.
  int16_t torque_permille(double force_n) const;
  double force_n(int16_t permille) const { return sign * double(permille) * rated_force_n / 1000.0; }
};

}  // namespace manip::canopen
