#include "manip/canopen/master.hpp"

#include <linux/can.h>
#include <linux/can/error.h>

#include <algorithm>
#include <cstring>

#include "manip/canopen/bus_load.hpp"

namespace manip::canopen {

const char* to_string(Phase p) {
  switch (p) {
    case Phase::Idle: return "idle";
    case Phase::Resetting: return "resetting (waiting for boot-up)";
    case Phase::Configuring: return "configuring (SDO start-up list)";
    case Phase::Starting: return "starting (NMT start)";
    case Phase::Cyclic: return "cyclic";
    case Phase::Faulted: return "faulted (safe state)";
    case Phase::ShuttingDown: return "shutting down";
    case Phase::Stopped: return "stopped";
    case Phase::Failed: return "start-up failed";
  }
  return "?";
}

EmcyAction emcy_policy(uint16_t code) {
  if (code == 0x0000) return EmcyAction::Reset;
  // Communication trouble the bus survives: CAN overrun, error passive,
  // recovered from bus-off (CiA 301 table 21). Bus-off itself is detected
  // on our side by the controller's error frames.
  if (code == 0x8110 || code == 0x8120 || code == 0x8140) return EmcyAction::Warning;
  // Temperature classes (0x4xxx) are warnings: the drive trips by itself
  // (and the statusword then reports Fault) before damage.
  if ((code & 0xF000) == 0x4000) return EmcyAction::Warning;
  // Everything else (current, voltage, hardware, software, sensors/encoder,
  // monitoring incl. following error and heartbeat, external, device
  // specific, unknown) faults the session.
  return EmcyAction::Fault;
}

std::string copley_event_status_text(uint32_t bits) {
  static const char* names[32] = {
      "short circuit detected", "drive over temperature", "over voltage", "under voltage",
      "motor temperature sensor active", "feedback error", "motor phasing error", "current output limited",
      "voltage output limited", "positive limit switch active", "negative limit switch active",
      "enable input not active", "drive disabled by software", "trying to stop motor", "motor brake activated",
      "PWM outputs disabled", "positive software limit", "negative software limit", "tracking error",
      "tracking warning", "drive in reset state", "position wrapped", "drive fault (latched)",
      "velocity limit reached", "acceleration limit reached", "position outside tracking window",
      "home switch active", "in motion", "velocity outside tracking window", "phase not initialized",
      "command input fault", "bit 31"};
  std::string s;
  for (int b = 0; b < 32; ++b) {
    if (!(bits & (1u << b))) continue;
    if (!s.empty()) s += ", ";
    s += names[b];
  }
  return s;
}

ErrorCode classify_error_frame(const CanFrame& f) {
  const uint32_t cls = f.id & CAN_ERR_MASK;
  if (cls & CAN_ERR_BUSOFF) return ErrorCode::BusOff;
  if (cls & CAN_ERR_CRTL) {
    const uint8_t d1 = f.dlc > 1 ? f.data[1] : 0;
    if (d1 & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE)) return ErrorCode::BusErrorPassive;
    if (d1 & (CAN_ERR_CRTL_RX_OVERFLOW | CAN_ERR_CRTL_TX_OVERFLOW)) return ErrorCode::ControllerProblem;
    if (d1 & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING)) return ErrorCode::None;  // warning level only
    if (d1 == CAN_ERR_CRTL_ACTIVE) return ErrorCode::None;
    return ErrorCode::ControllerProblem;
  }
  if (cls & (CAN_ERR_TX_TIMEOUT | CAN_ERR_TRX | CAN_ERR_ACK)) return ErrorCode::ControllerProblem;
  return ErrorCode::None;  // lost arbitration, protocol violations counted by the controller, restarted
}

Master::Master(const CanConfig& cfg, const std::string& bus_name) : mc_(cfg.master) {
  for (const auto& b : cfg.buses)
    if (b.name == bus_name) bus_ = b;
  for (const auto& d : cfg.drives)
    if (d.bus == bus_name) drives_.push_back(d);
  nodes_.resize(drives_.size());
  sdo_.resize(drives_.size());
  reset_edge_sent_.assign(drives_.size(), 0);
  for (std::size_t i = 0; i < drives_.size(); ++i) {
    nodes_[i].node_id = drives_[i].node_id;
    sdo_[i].set_node(drives_[i].node_id);
    sdo_[i].set_timeout_us(int64_t(mc_.sdo_timeout_ms) * 1000);
  }
  sync_period_us_ = mc_.sync_period_us;
  build_steps();
}

void Master::build_steps() {
  using K = SdoStep::Kind;
  using S = SdoStep::Store;
  steps_.clear();
  shutdown_steps_.clear();
  // Interpolation time period 0x60C2: value * 10^exponent s.
  uint32_t ip_value = mc_.sync_period_us;
  int ip_exp = -6;
  while (ip_value % 10 == 0 && ip_value > 0) { ip_value /= 10; ++ip_exp; }
  for (std::size_t i = 0; i < drives_.size(); ++i) {
    const DriveConfig& d = drives_[i];
    const uint8_t s = static_cast<uint8_t>(i);
    const uint8_t id = d.node_id;
    auto w = [&](uint16_t idx, uint8_t sub, uint8_t bytes, uint32_t v) { steps_.push_back({s, K::Write, idx, sub, bytes, v, 0xFFFFFFFF, S::None, false}); };
    auto v = [&](uint16_t idx, uint8_t sub, uint32_t expect, uint32_t mask = 0xFFFFFFFF, S st = S::None) { steps_.push_back({s, K::Verify, idx, sub, 4, expect, mask, st, false}); };
    auto r = [&](uint16_t idx, uint8_t sub, S st, bool opt = false) { steps_.push_back({s, K::Read, idx, sub, 4, 0, 0, st, opt}); };
    // Identity and the profile (CiA 301 0x1000, 0x1018; CiA 402 device type 402 = 0x0192).
    v(0x1000, 0, 0x0192, 0xFFFF, S::DeviceType);
    if (d.vendor_id) v(0x1018, 1, d.vendor_id, 0xFFFFFFFF, S::Vendor); else r(0x1018, 1, S::Vendor);
    if (d.product_code) v(0x1018, 2, d.product_code, 0xFFFFFFFF, S::Product); else r(0x1018, 2, S::Product);
    r(0x1018, 3, S::Revision, true);
    r(0x1018, 4, S::Serial, true);
    r(0x1008, 0, S::Name, true);
    r(0x1001, 0, S::ErrorRegister);
    // Rated current (0x6075, mA): 1000 per mille of target torque. A
    // mismatch would silently scale every force command.
    v(0x6075, 0, static_cast<uint32_t>(d.rated_current_a * 1000.0 + 0.5), 0xFFFFFFFF, S::RatedCurrent);
    // Heartbeats: the drive produces (0x1017) and consumes the master's (0x1016:01 = node<<16 | ms),
    // so it stops by itself if the master dies; 0x6007 says how (1 = fault).
    w(0x1017, 0, 2, d.heartbeat_producer_ms);
    v(0x1017, 0, d.heartbeat_producer_ms, 0xFFFF);
    w(0x1016, 1, 4, (uint32_t(mc_.node_id) << 16) | (d.master_heartbeat_timeout_ms & 0xFFFF));
    v(0x1016, 1, (uint32_t(mc_.node_id) << 16) | (d.master_heartbeat_timeout_ms & 0xFFFF));
    w(0x6007, 0, 2, static_cast<uint16_t>(d.abort_connection_option));
    // SYNC period (0x1006, us) and interpolation period (0x60C2).
    w(0x1006, 0, 4, mc_.sync_period_us);
    w(0x60C2, 1, 1, ip_value);
    w(0x60C2, 2, 1, static_cast<uint8_t>(static_cast<int8_t>(ip_exp)));
    // PDOs (CiA 301 §7.4.8.2 remap procedure, pre-operational): invalidate
    // the COB-ID (bit 31), sub0 = 0, entries, sub0 = N, transmission type,
    // validate; then read everything back. Unused PDOs are disabled so the
    // factory mapping cannot load the bus behind the budget's back.
    auto pdo = [&](uint16_t comm, uint16_t map, uint32_t cob, const PdoMapping& m) {
      w(comm, 1, 4, 0x80000000u | cob);
      if (m.count == 0) return;
      w(map, 0, 1, 0);
      for (uint8_t k = 0; k < m.count; ++k) w(map, uint8_t(k + 1), 4, mapping_entry(object_ref(m.objects[k])));
      w(map, 0, 1, m.count);
      w(comm, 2, 1, 1);  // synchronous, every SYNC (CiA 301 §7.5.2.35)
      w(comm, 1, 4, cob);
      v(map, 0, m.count, 0xFF);
      for (uint8_t k = 0; k < m.count; ++k) v(map, uint8_t(k + 1), mapping_entry(object_ref(m.objects[k])));
      v(comm, 2, 1, 0xFF);
      v(comm, 1, cob, 0x800007FF);
    };
    const PdoMapping none{};
    pdo(0x1400, 0x1600, cob::rpdo(0, id), d.rpdo);
    for (int n = 1; n < 4; ++n) pdo(uint16_t(0x1400 + n), uint16_t(0x1600 + n), cob::rpdo(n, id), none);
    pdo(0x1800, 0x1A00, cob::tpdo(0, id), d.tpdo);
    pdo(0x1801, 0x1A01, cob::tpdo(1, id), d.tpdo2);
    for (int n = 2; n < 4; ++n) pdo(uint16_t(0x1800 + n), uint16_t(0x1A00 + n), cob::tpdo(n, id), none);
    // Mode of operation: cyclic synchronous torque (CiA 402 0x6060 = 10), checked on 0x6061.
    w(0x6071, 0, 2, 0);           // zero torque preloaded before anything is enabled
    w(0x6040, 0, 2, 0);           // Disable voltage
    w(0x6060, 0, 1, 10);
    v(0x6061, 0, 10, 0xFF);
    // Shutdown: stop consuming our heartbeat before we stop producing it;
    // read the event status register for the log.
    shutdown_steps_.push_back({s, K::Write, 0x1016, 1, 4, 0, 0xFFFFFFFF, S::None, true});
    if (d.event_status_register) shutdown_steps_.push_back({s, K::Read, 0x1002, 0, 4, 0, 0, S::EventStatus, true});
  }
}

int Master::slot_of(uint8_t node) const {
  for (std::size_t i = 0; i < nodes_.size(); ++i)
    if (nodes_[i].node_id == node) return static_cast<int>(i);
  return -1;
}

void Master::log(const Error& e) {
  log_[log_n_ % kLogSize] = e;
  ++log_n_;
}

const Error& Master::log_entry(std::size_t i) const {
  const std::size_t first = log_n_ > kLogSize ? log_n_ - kLogSize : 0;
  return log_[(first + i) % kLogSize];
}

void Master::start(int64_t now) {
  now_us_ = now;
  error_ = {};
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    NodeStatus fresh;
    fresh.node_id = drives_[i].node_id;
    nodes_[i] = fresh;
    sdo_[i].reset();
  }
  step_ = 0;
  step_started_ = false;
  syncs_in_phase_ = 0;
  fault_reset_requested_ = false;
  faulted_before_shutdown_ = false;
  needs_restart_ = false;
  // Refuse an over-budget configuration before touching the bus.
  CanConfig c;
  c.master = mc_;
  c.buses = {bus_};
  c.drives = drives_;
  const auto budgets = compute_budgets(c);
  if (!budgets.empty() && !budgets[0].ok()) {
    error_ = Error{ErrorCode::BusLoadTooHigh, 0, 0, 0, static_cast<uint32_t>(budgets[0].load * 1000 + 0.5),
                   static_cast<uint32_t>(mc_.max_bus_load * 1000 + 0.5), now};
    log(error_);
    phase_ = Phase::Failed;
    return;
  }
  phase_ = Phase::Resetting;
  nmt_reset_pending_ = true;
  deadline_us_ = now + int64_t(mc_.boot_timeout_ms) * 1000;
  next_heartbeat_us_ = now;
}

void Master::fail(const Error& e, FrameBuffer& tx) {
  error_ = e;
  error_.time_us = now_us_;
  log(error_);
  phase_ = Phase::Failed;
  // Nothing was enabled during start-up; leave every node in pre-operational
  // so no PDO is processed.
  for (const auto& n : nodes_) tx.push(nmt_frame(NmtCommand::EnterPreOperational, n.node_id));
}

void Master::enter_fault(const Error& e, FrameBuffer& tx) {
  if (phase_ == Phase::Resetting || phase_ == Phase::Configuring || phase_ == Phase::Starting) return fail(e, tx);
  if (phase_ == Phase::Failed || phase_ == Phase::Stopped || phase_ == Phase::Idle) {
    log(e);
    return;
  }
  if (phase_ == Phase::Faulted || phase_ == Phase::ShuttingDown) {  // keep the first reason
    if (!recoverable(e.code)) needs_restart_ = true;
    Error x = e;
    x.time_us = now_us_;
    log(x);
    return;
  }
  error_ = e;
  error_.time_us = now_us_;
  log(error_);
  phase_ = Phase::Faulted;
  fault_reset_requested_ = false;
  needs_restart_ = !recoverable(e.code);
  // Safe state in this very call: torque 0 and Disable voltage, applied at a
  // SYNC sent right behind them (RPDOs are synchronous).
  for (auto& n : nodes_) {
    n.controlword = cia402::cw::kDisableVoltage;
    n.torque_permille = 0;
    n.operation_enabled = false;
  }
  emit_cyclic(tx);
  next_sync_us_ = now_us_ + sync_period_us_;
}

void Master::fault(const Error& e, FrameBuffer& tx) { enter_fault(e, tx); }

bool Master::recoverable(ErrorCode c) const {
  // An uncommanded disable (e-stop / STO) and an open e-stop chain keep the
  // drives' configuration: the operator's reset re-enables (2-3-4) once the
  // backend no longer reports the chain open.
  return c == ErrorCode::DriveFault || c == ErrorCode::EmcyFault || c == ErrorCode::TpdoMissing ||
         c == ErrorCode::OperatorStop || c == ErrorCode::UncommandedDisable || c == ErrorCode::EStopChain;
}

bool Master::request_fault_reset() {
  // A later non-recoverable event (reboot, heartbeat loss, bus error) while
  // faulted also needs a restart: e.g. TPDOs stop first when a drive loses
  // power, the boot-up comes later and its configuration is gone.
  if (phase_ != Phase::Faulted || needs_restart_) return false;
  fault_reset_requested_ = true;
  fault_reset_deadline_us_ = now_us_ + int64_t(mc_.fault_reset_timeout_ms) * 1000;
  std::fill(reset_edge_sent_.begin(), reset_edge_sent_.end(), uint8_t{0});
  return true;
}

void Master::request_shutdown(int64_t now) {
  if (phase_ == Phase::Idle || phase_ == Phase::Stopped || phase_ == Phase::Failed) {
    phase_ = Phase::Stopped;
    return;
  }
  faulted_before_shutdown_ = phase_ == Phase::Faulted;
  phase_ = Phase::ShuttingDown;
  shutdown_stage_ = 0;
  shutdown_until_us_ = now + 3 * sync_period_us_;
  for (auto& n : nodes_) {
    n.controlword = cia402::cw::kDisableVoltage;
    n.torque_permille = 0;
  }
}

Error Master::request_sdo(uint8_t node, uint16_t index, uint8_t sub) {
  // Ad-hoc SDOs are never offered: a confirmed SDO costs milliseconds and
  // would stall the loop. Start-up/shutdown SDOs go through the step lists.
  return Error{ErrorCode::SdoNotAllowed, node, index, sub, 0, 0, now_us_};
}

void Master::set_command(std::size_t slot, uint16_t controlword, int16_t torque) {
  if (slot >= nodes_.size()) return;
  NodeStatus& n = nodes_[slot];
  if (phase_ == Phase::Cyclic) {
    if (controlword != cia402::cw::kEnableOperation) n.operation_enabled = false;  // commanded departure
    n.controlword = controlword;
    // Zero torque unless the drive is (being) enabled: targets are preloaded
    // with zero before Enable operation.
    n.torque_permille = cia402::decode(n.statusword) == cia402::State::OperationEnabled ? torque : 0;
  } else if (phase_ == Phase::Faulted) {
    n.controlword = (controlword == cia402::cw::kFaultResetBit) ? controlword : cia402::cw::kDisableVoltage;
    n.torque_permille = 0;
  }
}

void Master::emit_cyclic(FrameBuffer& tx) {
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    const NodeStatus& n = nodes_[i];
    const PdoMapping& m = drives_[i].rpdo;
    CanFrame f;
    f.id = cob::rpdo(0, n.node_id);
    for (int k = 0; k < m.count; ++k) {
      const auto o = m.objects[k];
      if (o == PdoObject::Controlword) { put_u16(f.data + f.dlc, n.controlword); f.dlc += 2; }
      else if (o == PdoObject::TargetTorque) { put_u16(f.data + f.dlc, static_cast<uint16_t>(n.torque_permille)); f.dlc += 2; }
    }
    tx.push(f);
  }
  tx.push(make_frame(cob::kSync, {}));
  ++syncs_sent_;
  ++syncs_in_phase_;
}

void Master::on_heartbeat(int slot, const CanFrame& f, FrameBuffer& tx) {
  NodeStatus& n = nodes_[static_cast<std::size_t>(slot)];
  if (f.dlc < 1) return;
  const auto state = static_cast<NmtState>(f.data[0] & 0x7F);
  if (state == NmtState::BootUp) {
    if (phase_ == Phase::Resetting) {
      n.booted = true;
    } else if (n.booted && phase_ != Phase::Stopped && phase_ != Phase::Failed && phase_ != Phase::Idle) {
      // A boot-up in a session = the drive was power cycled or reset: its
      // configuration is gone. Only a new start() recovers (re-initialisation).
      n.nmt = state;
      n.last_heartbeat_us = now_us_;
      n.booted = false;
      return enter_fault(Error{ErrorCode::NodeRebooted, n.node_id, 0, 0, 0, 0, now_us_}, tx);
    }
  }
  n.nmt = state;
  n.last_heartbeat_us = now_us_;
  n.heartbeat_lost = false;
  if (phase_ == Phase::Cyclic && state != NmtState::Operational)
    enter_fault(Error{ErrorCode::NmtStateWrong, n.node_id, 0, 0, f.data[0], 0, now_us_}, tx);
}

void Master::on_emcy(int slot, const CanFrame& f, FrameBuffer& tx) {
  NodeStatus& n = nodes_[static_cast<std::size_t>(slot)];
  const uint16_t code = f.dlc >= 2 ? get_u16(f.data) : 0;
  const uint8_t reg = f.dlc >= 3 ? f.data[2] : 0;
  n.last_emcy_code = code;
  ++n.emcy_count;
  Error e{ErrorCode::EmcyWarning, n.node_id, 0, 0, code, reg, now_us_};
  switch (emcy_policy(code)) {
    case EmcyAction::Reset:
    case EmcyAction::Warning:
      log(e);
      break;
    case EmcyAction::Fault:
      e.code = ErrorCode::EmcyFault;
      if (phase_ == Phase::ShuttingDown || phase_ == Phase::Stopped) log(e);
      else enter_fault(e, tx);
      break;
  }
}

void Master::on_tpdo(int slot, int pdo, const CanFrame& f, FrameBuffer& tx) {
  NodeStatus& n = nodes_[static_cast<std::size_t>(slot)];
  const PdoMapping& m = pdo == 0 ? drives_[static_cast<std::size_t>(slot)].tpdo : drives_[static_cast<std::size_t>(slot)].tpdo2;
  if (m.count == 0 || f.dlc != m.bytes()) return;  // length error: treated as missing
  int b = 0;
  for (int k = 0; k < m.count; ++k) {
    switch (m.objects[k]) {
      case PdoObject::Statusword: n.statusword = get_u16(f.data + b); b += 2; break;
      case PdoObject::PositionActual: n.position_counts = static_cast<int32_t>(get_u32(f.data + b)); b += 4; break;
      case PdoObject::VelocityActual: n.velocity_units = static_cast<int32_t>(get_u32(f.data + b)); b += 4; break;
      case PdoObject::DigitalInputs: n.digital_inputs = get_u32(f.data + b); b += 4; break;
      default: b += object_ref(m.objects[k]).bits / 8; break;
    }
  }
  if (pdo == 0) n.tpdo1_seen = true; else n.tpdo2_seen = true;
  n.nmt = NmtState::Operational;  // PDOs are only sent in operational (CiA 301 §7.3.2)
  ++n.tpdo_received;
  n.has_feedback = true;
  n.feedback_time_us = now_us_;
  if (pdo == 0 && (phase_ == Phase::Cyclic)) {
    const auto st = cia402::decode(n.statusword);
    if (st == cia402::State::Fault || st == cia402::State::FaultReactionActive) {
      enter_fault(Error{ErrorCode::DriveFault, n.node_id, 0, 0, n.statusword, 0, now_us_}, tx);
    } else if (n.controlword == cia402::cw::kEnableOperation) {
      // The master asks for Operation enabled (transition 4, then holds it).
      // A drive that leaves it by itself without a CANopen fault (STO / e-stop
      // contactor: bit 4 off, a fall to Switch on disabled (transitions 9/10/
      // 12 taken by the drive) or Ready to switch on, Quick stop active, any
      // other state) must not be walked back through 2-3-4 when its power
      // returns: fault the bus (safe state on every bus, both axes) until the
      // operator's reset (IEC 60204-1, emergency stop: no automatic restart).
      const bool powered = st == cia402::State::OperationEnabled && (n.statusword & cia402::sw::kVoltageEnabled);
      if (powered) {
        n.operation_enabled = true;
      } else if (n.operation_enabled) {
        n.operation_enabled = false;
        enter_fault(Error{ErrorCode::UncommandedDisable, n.node_id, 0, 0, n.statusword, 0, now_us_}, tx);
      }
    }
  }
}

void Master::handle(int64_t now, std::span<const CanFrame> rx, FrameBuffer& tx) {
  now_us_ = now;
  for (const CanFrame& f : rx) {
    if (f.is_error()) {
      const ErrorCode c = classify_error_frame(f);
      Error e{c, 0, 0, 0, f.id, f.dlc > 1 ? f.data[1] : 0u, now};
      if (c == ErrorCode::None) { e.code = ErrorCode::ControllerProblem; log(e); continue; }
      if (phase_ != Phase::Idle && phase_ != Phase::Stopped) enter_fault(e, tx);
      else log(e);
      continue;
    }
    if (f.is_rtr() || f.id == cob::kNmt || f.id == cob::kSync) continue;
    const uint32_t fc = function_code(f.id);
    const uint8_t node = node_of(f.id);
    if (node == 0 || node == mc_.node_id) continue;
    const bool from_slave = fc == 0x080 || fc == 0x180 || fc == 0x280 || fc == 0x380 || fc == 0x480 || fc == 0x580 || fc == 0x700;
    if (!from_slave) continue;  // requests of another master / RPDOs: not ours to judge
    const int slot = slot_of(node);
    if (phase_ == Phase::Idle || phase_ == Phase::Stopped || phase_ == Phase::Failed) {
      if (slot >= 0 && fc == 0x700 && f.dlc >= 1) { nodes_[size_t(slot)].nmt = static_cast<NmtState>(f.data[0]); nodes_[size_t(slot)].last_heartbeat_us = now; }
      continue;
    }
    if (slot < 0) {
      uint8_t expected = 0;
      for (const auto& c : sdo_) if (c.busy()) expected = c.node();
      enter_fault(Error{ErrorCode::UnexpectedNode, node, 0, 0, f.id, expected, now}, tx);
      continue;
    }
    switch (fc) {
      case 0x700: on_heartbeat(slot, f, tx); break;
      case 0x080: on_emcy(slot, f, tx); break;
      case 0x180: on_tpdo(slot, 0, f, tx); break;
      case 0x280: on_tpdo(slot, 1, f, tx); break;
      case 0x580: {
        SdoClient& c = sdo_[static_cast<std::size_t>(slot)];
        if (c.busy()) c.on_frame(now, f, tx);
        else if (phase_ == Phase::Configuring || phase_ == Phase::ShuttingDown)
          // An answer nobody asked for: another node answering with this id.
          enter_fault(Error{ErrorCode::UnexpectedNode, node, 0, 0, f.id, 0, now}, tx);
        else log(Error{ErrorCode::UnexpectedNode, node, 0, 0, f.id, 0, now});
        break;
      }
      default: break;
    }
  }
}

void Master::check_heartbeats(FrameBuffer& tx) {
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    NodeStatus& n = nodes_[i];
    if (!n.booted || n.heartbeat_lost) continue;  // (Resetting: the boot deadline applies)
    const int64_t age = now_us_ - n.last_heartbeat_us;
    if (age > int64_t(drives_[i].heartbeat_timeout_ms) * 1000) {
      n.heartbeat_lost = true;
      enter_fault(Error{ErrorCode::HeartbeatLost, n.node_id, 0, 0, 0, static_cast<uint32_t>(age / 1000), now_us_}, tx);
      return;
    }
  }
}

void Master::check_tpdos(FrameBuffer& tx) {
  if (syncs_in_phase_ < 2) return;  // the first SYNC's TPDO is still on its way
  for (std::size_t i = 0; i < nodes_.size(); ++i) {
    NodeStatus& n = nodes_[i];
    const bool ok = n.tpdo1_seen && (drives_[i].tpdo2.count == 0 || n.tpdo2_seen);
    n.tpdo1_seen = n.tpdo2_seen = false;
    if (ok) {
      n.tpdo_missed_consecutive = 0;
      continue;
    }
    ++n.tpdo_missed_consecutive;
    ++n.tpdo_missed_total;
    if (n.tpdo_missed_consecutive >= mc_.tpdo_miss_limit && phase_ == Phase::Cyclic)
      enter_fault(Error{ErrorCode::TpdoMissing, n.node_id, 0, 0, 0, n.tpdo_missed_consecutive, now_us_}, tx);
  }
}

void Master::run_steps(std::vector<SdoStep>& steps, FrameBuffer& tx, bool startup) {
  while (step_ < steps.size()) {
    const SdoStep& s = steps[step_];
    SdoClient& c = sdo_[s.slot];
    if (!step_started_ && s.store == SdoStep::Store::EventStatus && !faulted_before_shutdown_) {
      ++step_;
      continue;
    }
    if (!step_started_) {
      if (s.kind == SdoStep::Kind::Write) c.download_u32(now_us_, s.index, s.sub, s.value, s.bytes, tx);
      else c.upload(now_us_, s.index, s.sub, tx);
      step_started_ = true;
      return;
    }
    c.poll(now_us_, tx);
    if (c.busy()) return;
    step_started_ = false;
    if (c.status() == SdoClient::Status::Failed) {
      if (s.optional && c.error().code == ErrorCode::SdoAbort) { ++step_; continue; }
      if (startup) return fail(c.error(), tx);
      log(c.error());
      ++step_;
      continue;
    }
    const uint32_t val = c.value_u32();
    NodeIdentity& id = nodes_[s.slot].identity;
    switch (s.store) {
      case SdoStep::Store::DeviceType: id.device_type = val; break;
      case SdoStep::Store::Vendor: id.vendor_id = val; break;
      case SdoStep::Store::Product: id.product_code = val; break;
      case SdoStep::Store::Revision: id.revision = val; break;
      case SdoStep::Store::Serial: id.serial = val; break;
      case SdoStep::Store::ErrorRegister:
        id.error_register = static_cast<uint8_t>(val);
        if (val) log(Error{ErrorCode::EmcyWarning, nodes_[s.slot].node_id, s.index, s.sub, 0, val, now_us_});
        break;
      case SdoStep::Store::RatedCurrent: id.rated_current_ma = val; break;
      case SdoStep::Store::EventStatus: id.event_status = val; id.event_status_read = true; break;
      case SdoStep::Store::Name: {
        const auto d = c.data();
        const std::size_t n = std::min(d.size(), id.name.size() - 1);
        std::memcpy(id.name.data(), d.data(), n);
        id.name[n] = '\0';
        break;
      }
      case SdoStep::Store::None: break;
    }
    if (s.kind == SdoStep::Kind::Verify && (val & s.mask) != (s.value & s.mask)) {
      Error e{ErrorCode::VerifyMismatch, nodes_[s.slot].node_id, s.index, s.sub, val & s.mask, s.value & s.mask, now_us_};
      if (startup) return fail(e, tx);
      log(e);
    }
    ++step_;
  }
}

void Master::update(int64_t now, FrameBuffer& tx) {
  now_us_ = now;
  if (phase_ == Phase::Idle || phase_ == Phase::Stopped || phase_ == Phase::Failed) return;
  // Master heartbeat producer: the drives' consumers (0x1016) watch it.
  if (now >= next_heartbeat_us_) {
    const uint8_t st = (phase_ == Phase::Cyclic || phase_ == Phase::Faulted) ? 0x05 : 0x7F;
    tx.push(make_frame(cob::heartbeat(mc_.node_id), {st}));
    next_heartbeat_us_ = now + int64_t(mc_.heartbeat_ms) * 1000;
  }
  switch (phase_) {
    case Phase::Resetting: {
      if (nmt_reset_pending_) {
        // Reset node (not only communication): a re-initialisation after an
        // e-stop power cycle then starts from the same state as a cold boot.
        for (const auto& n : nodes_) tx.push(nmt_frame(NmtCommand::ResetNode, n.node_id));
        nmt_reset_pending_ = false;
        return;
      }
      bool all = true;
      for (const auto& n : nodes_) all &= n.booted;
      if (all) {
        phase_ = Phase::Configuring;
        step_ = 0;
        step_started_ = false;
        for (auto& n : nodes_) n.last_heartbeat_us = now;  // boot-up was the first heartbeat
        run_steps(steps_, tx, true);
        return;
      }
      if (now >= deadline_us_) {
        for (const auto& n : nodes_)
          if (!n.booted)
            return fail(Error{ErrorCode::BootTimeout, n.node_id, 0, 0, 0, mc_.boot_timeout_ms, now}, tx);
      }
      return;
    }
    case Phase::Configuring:
      check_heartbeats(tx);
      if (phase_ != Phase::Configuring) return;
      run_steps(steps_, tx, true);
      if (phase_ == Phase::Configuring && step_ >= steps_.size()) {
        for (const auto& n : nodes_) tx.push(nmt_frame(NmtCommand::Start, n.node_id));
        phase_ = Phase::Starting;
        deadline_us_ = now + int64_t(mc_.enable_timeout_ms) * 1000 + int64_t(mc_.heartbeat_ms) * 1000;
        next_sync_us_ = now + sync_period_us_;
        syncs_in_phase_ = 0;
      }
      return;
    case Phase::Starting: {
      check_heartbeats(tx);
      if (phase_ != Phase::Starting) return;
      if (now >= next_sync_us_) {
        emit_cyclic(tx);
        next_sync_us_ += sync_period_us_;
      }
      bool all = true;
      for (const auto& n : nodes_) all &= n.nmt == NmtState::Operational || n.has_feedback;
      if (all) {
        phase_ = Phase::Cyclic;
        syncs_in_phase_ = 0;
        for (auto& n : nodes_) n.tpdo1_seen = n.tpdo2_seen = false;
      } else if (now >= deadline_us_) {
        for (const auto& n : nodes_)
          if (!(n.nmt == NmtState::Operational || n.has_feedback))
            return fail(Error{ErrorCode::NmtStateWrong, n.node_id, 0, 0, static_cast<uint32_t>(n.nmt), 0, now}, tx);
      }
      return;
    }
    case Phase::Cyclic:
    case Phase::Faulted: {
      check_heartbeats(tx);
      if (now < next_sync_us_) return;
      {
        const Phase before = phase_;
        check_tpdos(tx);
        if (phase_ != before) return;  // the fault already sent the safe RPDOs + SYNC
      }
      if (phase_ == Phase::Faulted) {
        bool any_fault = false;
        for (std::size_t i = 0; i < nodes_.size(); ++i) {
          NodeStatus& n = nodes_[i];
          const auto st = cia402::decode(n.statusword);
          const bool in_fault = st == cia402::State::Fault || st == cia402::State::FaultReactionActive;
          any_fault |= in_fault;
          // One rising edge of 0x6040 bit 7 per operator request (CiA 402
          // transition 15): a drive whose cause persists is not reset again
          // and again behind the operator's back.
          const bool want_edge = fault_reset_requested_ && !reset_edge_sent_[i];
          const auto step = cia402::master_step(n.statusword, cia402::Target::Disabled, want_edge, n.controlword);
          if (step.transition == 15) reset_edge_sent_[i] = 1;
          n.controlword = step.controlword;
          n.torque_permille = 0;
        }
        if (fault_reset_requested_ && any_fault && now >= fault_reset_deadline_us_) {
          fault_reset_requested_ = false;
          ++fault_resets_failed_;
          for (const auto& n : nodes_) {
            const auto st = cia402::decode(n.statusword);
            if (st == cia402::State::Fault || st == cia402::State::FaultReactionActive) {
              log(Error{ErrorCode::FaultResetFailed, n.node_id, 0, 0, n.statusword, 0, now});
              break;
            }
          }
        }
        if (fault_reset_requested_ && !any_fault) {
          // Acknowledged and every drive out of Fault: back to cyclic, disabled.
          fault_reset_requested_ = false;
          phase_ = Phase::Cyclic;
          syncs_in_phase_ = 0;
          for (auto& n : nodes_) { n.tpdo_missed_consecutive = 0; n.tpdo1_seen = n.tpdo2_seen = false; }
        }
      }
      emit_cyclic(tx);
      next_sync_us_ += sync_period_us_;
      if (now >= next_sync_us_) {  // late by a whole period: resynchronise, note it
        log(Error{ErrorCode::CycleOverrun, 0, 0, 0, 0, static_cast<uint32_t>(now - next_sync_us_), now});
        next_sync_us_ = now + sync_period_us_;
      }
      return;
    }
    case Phase::ShuttingDown: {
      if (shutdown_stage_ == 0) {
        if (now >= next_sync_us_) {
          emit_cyclic(tx);  // Disable voltage + zero torque for a few periods
          next_sync_us_ = now + sync_period_us_;
        }
        if (now < shutdown_until_us_) return;
        for (const auto& n : nodes_) tx.push(nmt_frame(NmtCommand::EnterPreOperational, n.node_id));
        shutdown_stage_ = 1;
        step_ = 0;
        step_started_ = false;
        return;
      }
      // Shutdown SDOs (the event status register only after a fault).
      run_steps(shutdown_steps_, tx, false);
      if (step_ >= shutdown_steps_.size()) phase_ = Phase::Stopped;
      return;
    }
    default: return;
  }
}

bool Master::poll(int64_t now, CanPort& port) {
  CanFrame rx[64];
  FrameBuffer tx;
  std::size_t n = 0;
  do {
    n = port.receive(std::span<CanFrame>(rx, 64));
    handle(now, std::span<const CanFrame>(rx, n), tx);
  } while (n == 64);
  update(now, tx);
  bool ok = true;
  for (const CanFrame& f : tx) ok &= port.send(f);
  return ok;
}

}  // namespace manip::canopen
