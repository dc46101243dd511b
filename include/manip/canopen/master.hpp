#pragma once
// The passive CANopen master of one bus (in the spirit of lely-core's
// can_net): fed with received frames and the current time, it appends the
// frames to send to a caller-provided FrameBuffer. No threads, no locks, no
// allocation after construction; deterministic under simulated time.
//
// Life cycle (phase):
//   Idle -> start() -> Resetting (NMT reset node, wait boot-up before the boot
//   deadline) -> Configuring (SDO list: identity, heartbeat 0x1016/0x1017,
//   SYNC period, PDO remap in pre-operational with read-back, mode 10)
//   -> Starting (NMT start; SYNC + RPDOs with disable voltage and zero torque)
//   -> Cyclic (SYNC at the drive rate, RPDO1, TPDO monitoring, heartbeat
//   consumer, EMCY policy) -> request_shutdown() -> ShuttingDown -> Stopped.
//   Any start-up problem: Failed (nothing was enabled; nodes sent to
//   pre-operational). Any cyclic problem: Faulted (safe commands sent in the
//   same call: controlword Disable voltage, target torque 0, plus a SYNC).
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "manip/canopen/cia402.hpp"
#include "manip/canopen/config.hpp"
#include "manip/canopen/error.hpp"
#include "manip/canopen/frame.hpp"
#include "manip/canopen/sdo.hpp"

namespace manip::canopen {

enum class Phase : uint8_t { Idle, Resetting, Configuring, Starting, Cyclic, Faulted, ShuttingDown, Stopped, Failed };
const char* to_string(Phase p);

enum class EmcyAction : uint8_t { Reset, Warning, Fault };
// The documented EMCY policy (docs/hardware.md): which EMCY error codes
// fault the session and which are logged warnings.
EmcyAction emcy_policy(uint16_t error_code);

// Copley event status register (0x1002 mirror of 0x2180) bit names; empty
// string if no bit set. Bit assignment from Copley's CANopen programmer's
// manual; verify against your firmware revision.
std::string copley_event_status_text(uint32_t bits);

// SocketCAN error frame -> error code (None for harmless classes).
// Input: CanFrame with kError flag, id = error class bits (CAN_ERR_* of
// <linux/can/error.h> without CAN_ERR_FLAG), data = error details.
ErrorCode classify_error_frame(const CanFrame& f);

struct NodeIdentity {
  uint32_t device_type = 0;   // 0x1000
  uint32_t vendor_id = 0;     // 0x1018:01
  uint32_t product_code = 0;  // 0x1018:02
  uint32_t revision = 0;      // 0x1018:03
  uint32_t serial = 0;        // 0x1018:04
  uint8_t error_register = 0; // 0x1001
  uint32_t rated_current_ma = 0;  // 0x6075
  uint32_t event_status = 0;  // 0x1002 (read after a fault, if configured)
  bool event_status_read = false;
  std::array<char, 64> name{};  // 0x1008 (segmented upload)
};

struct NodeStatus {
  uint8_t node_id = 0;
  NmtState nmt = NmtState::Unknown;
  bool booted = false;
  int64_t last_heartbeat_us = 0;
  bool heartbeat_lost = false;   // reported once until the next heartbeat
  uint16_t statusword = 0;
  int32_t position_counts = 0;
  int32_t velocity_units = 0;
  uint32_t digital_inputs = 0;   // 0x60FD, if mapped
  bool has_feedback = false;
  int64_t feedback_time_us = 0;
  uint32_t tpdo_received = 0;
  uint32_t tpdo_missed_consecutive = 0;
  uint32_t tpdo_missed_total = 0;
  bool tpdo1_seen = false;
  bool tpdo2_seen = false;
  uint16_t controlword = 0;      // commanded (RPDO1)
  // The drive reported Operation enabled with 0x6041 bit 4 (voltage enabled)
  // while the master commands Enable operation (0x0F): from then on, any
  // other report until the master commands something else is a departure
  // the master did not command (ErrorCode::UncommandedDisable).
  bool operation_enabled = false;
  int16_t torque_permille = 0;   // commanded (RPDO1)
  uint16_t last_emcy_code = 0;
  uint32_t emcy_count = 0;
  NodeIdentity identity;
};

struct SdoStep {
  enum class Kind : uint8_t { Write, Read, Verify };
  enum class Store : uint8_t { None, DeviceType, Vendor, Product, Revision, Serial, ErrorRegister, RatedCurrent, EventStatus, Name };
  uint8_t slot = 0;  // node slot in this master
  Kind kind = Kind::Write;
  uint16_t index = 0;
  uint8_t sub = 0;
  uint8_t bytes = 4;
  uint32_t value = 0;        // written value / expected value
  uint32_t mask = 0xFFFFFFFF;// compare mask for Verify
  Store store = Store::None;
  bool optional = false;     // an abort is not an error (object may not exist)
};

class Master {
 public:
  // Builds the SDO lists; all allocation happens here.
  Master(const CanConfig& cfg, const std::string& bus_name);

  // Start (or restart after a failure/power cycle): clears every node's
  // state, including latched heartbeat monitoring.
  void start(int64_t now_us);
  // handle(): received frames (may append immediate frames: SDO, safe state).
  // update(): timers, start-up sequencing and the cyclic SYNC/RPDO emission.
  void handle(int64_t now_us, std::span<const CanFrame> rx, FrameBuffer& tx);
  void update(int64_t now_us, FrameBuffer& tx);
  void process(int64_t now_us, std::span<const CanFrame> rx, FrameBuffer& tx) {
    handle(now_us, rx, tx);
    update(now_us, tx);
  }
  // Receive from the port, process, send. Returns false if a send failed.
  bool poll(int64_t now_us, CanPort& port);

  Phase phase() const { return phase_; }
  bool running() const { return phase_ == Phase::Cyclic; }
  const Error& error() const { return error_; }
  std::size_t node_count() const { return nodes_.size(); }
  const NodeStatus& node(std::size_t slot) const { return nodes_[slot]; }
  const DriveConfig& drive(std::size_t slot) const { return drives_[slot]; }
  int64_t sync_period_us() const { return sync_period_us_; }
  uint32_t syncs_sent() const { return syncs_sent_; }

  // Cyclic command of one node (RPDO1 content at the next SYNC). Ignored
  // outside Cyclic/Faulted; in Faulted only Disable voltage / fault reset pass
  // and the torque is forced to zero.
  void set_command(std::size_t slot, uint16_t controlword, int16_t torque_permille);
  // External fault (e.g. a safety limit in the controller): safe state now.
  void fault(const Error& e, FrameBuffer& tx);
  // Operator fault acknowledge. Only faults the drives can recover from
  // (drive fault, EMCY fault, missing TPDOs, a drive that left Operation
  // enabled by itself, an open e-stop chain) are acknowledgeable; the edge on
  // controlword bit 7 is then produced by cia402::master_step, exactly once
  // per request and per drive in Fault (CiA 402 transition 15). A drive still
  // in Fault master.enable_timeout_ms after the request (its cause persists)
  // ends the attempt: logged as FaultResetFailed, the bus stays Faulted and
  // acknowledgeable. Returns false if the fault needs a full restart (start()).
  bool request_fault_reset();
  bool fault_reset_pending() const { return fault_reset_requested_; }
  // Faulted, and request_fault_reset() would be accepted.
  bool fault_acknowledgeable() const { return phase_ == Phase::Faulted && !needs_restart_; }
  // Number of reset attempts that ended with a drive still in Fault.
  uint32_t fault_resets_failed() const { return fault_resets_failed_; }
  void request_shutdown(int64_t now_us);
  // SDOs are start-up/shutdown only: always refused here during the cyclic phase.
  Error request_sdo(uint8_t node, uint16_t index, uint8_t sub);

  // Event log (warnings and faults), fixed ring, newest last.
  static constexpr std::size_t kLogSize = 64;
  std::size_t log_count() const { return log_n_ < kLogSize ? log_n_ : kLogSize; }
  const Error& log_entry(std::size_t i) const;  // 0 = oldest kept
  std::size_t steps_total() const { return steps_.size(); }
  std::size_t steps_done() const { return step_; }

 private:
  void fail(const Error& e, FrameBuffer& tx);
  void enter_fault(const Error& e, FrameBuffer& tx);
  void log(const Error& e);
  int slot_of(uint8_t node) const;
  void on_heartbeat(int slot, const CanFrame& f, FrameBuffer& tx);
  void on_emcy(int slot, const CanFrame& f, FrameBuffer& tx);
  void on_tpdo(int slot, int n, const CanFrame& f, FrameBuffer& tx);
  void run_steps(std::vector<SdoStep>& steps, FrameBuffer& tx, bool startup);
  void emit_cyclic(FrameBuffer& tx);
  void check_tpdos(FrameBuffer& tx);
  void check_heartbeats(FrameBuffer& tx);
  bool recoverable(ErrorCode c) const;
  void build_steps();

  MasterConfig mc_;
  BusConfig bus_;
  std::vector<DriveConfig> drives_;
  std::vector<NodeStatus> nodes_;
  std::vector<SdoClient> sdo_;
  std::vector<SdoStep> steps_;
  std::vector<SdoStep> shutdown_steps_;
  std::size_t step_ = 0;
  bool step_started_ = false;
  Phase phase_ = Phase::Idle;
  Error error_{};
  int64_t now_us_ = 0;
  int64_t deadline_us_ = 0;
  int64_t sync_period_us_ = 500;
  int64_t next_sync_us_ = 0;
  int64_t next_heartbeat_us_ = 0;
  int64_t shutdown_until_us_ = 0;
  uint32_t syncs_sent_ = 0;
  uint32_t syncs_in_phase_ = 0;
  bool nmt_reset_pending_ = false;
  bool fault_reset_requested_ = false;
  int64_t fault_reset_deadline_us_ = 0;
  std::vector<uint8_t> reset_edge_sent_;  // per node: the one edge of this request is out
  uint32_t fault_resets_failed_ = 0;
  bool needs_restart_ = false;
  bool faulted_before_shutdown_ = false;
  int shutdown_stage_ = 0;
  std::array<Error, kLogSize> log_{};
  std::size_t log_n_ = 0;
};

}  // namespace manip::canopen
