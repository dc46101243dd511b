#include "manip/canopen/simulated_drive.hpp"

#include <algorithm>
#include <cmath>

#include "manip/canopen/sdo.hpp"

namespace manip::canopen {

namespace {
constexpr uint32_t kInvalid = 0x80000000u;  // COB-ID bit 31: PDO not valid (CiA 301 §7.5.2.35)
bool is_mapping(uint16_t i) { return (i >= 0x1600 && i <= 0x1603) || (i >= 0x1A00 && i <= 0x1A03); }
bool is_live(uint16_t i) {
  return i == 0x6041 || i == 0x6064 || i == 0x606C || i == 0x6061 || i == 0x6077 || i == 0x60FD;
}
}  // namespace

SimulatedDrive::SimulatedDrive(const SimDriveParams& p) : p_(p) {
  build_od();
  position_m_ = p.initial_position_m;
  powered_ = true;
  boot_at_us_ = p.boot_delay_us;  // relative to the first process() time
  sdo_buf_.reserve(256);
  user_string_.reserve(256);
}

void SimulatedDrive::build_od() {
  const uint8_t id = p_.node_id;
  auto add = [&](uint16_t i, uint8_t s, uint8_t b, bool w, bool m, uint32_t v) {
    od_.push_back(Entry{i, s, b, w, m, v, v});
  };
  add(0x1000, 0, 4, false, false, p_.device_type);
  add(0x1001, 0, 1, false, true, 0);
  if (p_.has_event_status) add(0x1002, 0, 4, false, true, 0);
  add(0x1005, 0, 4, true, false, 0x80);
  add(0x1006, 0, 4, true, false, 0);
  add(0x1016, 0, 1, false, false, 1);
  add(0x1016, 1, 4, true, false, 0);
  add(0x1017, 0, 2, true, false, 0);
  add(0x1018, 0, 1, false, false, 4);
  add(0x1018, 1, 4, false, false, p_.vendor_id);
  add(0x1018, 2, 4, false, false, p_.product_code);
  add(0x1018, 3, 4, false, false, p_.revision);
  add(0x1018, 4, 4, false, false, p_.serial);
  // PDO communication/mapping parameters (CiA 301 §7.5.2.35-38). Factory
  // defaults deliberately differ from manip's mapping, and TPDO2 is valid, so
  // an unconfigured drive would load the bus: the master must remap/disable.
  for (int n = 0; n < 4; ++n) {
    add(uint16_t(0x1400 + n), 0, 1, false, false, 2);
    add(uint16_t(0x1400 + n), 1, 4, true, false, (n == 0 ? 0u : kInvalid) | cob::rpdo(n, id));
    add(uint16_t(0x1400 + n), 2, 1, true, false, 255);
    add(uint16_t(0x1600 + n), 0, 1, true, false, n == 0 ? 1 : 0);
    for (uint8_t s = 1; s <= 8; ++s) add(uint16_t(0x1600 + n), s, 4, true, false, (n == 0 && s == 1) ? 0x60400010u : 0u);
    add(uint16_t(0x1800 + n), 0, 1, false, false, 2);
    add(uint16_t(0x1800 + n), 1, 4, true, false, (n <= 1 ? 0u : kInvalid) | cob::tpdo(n, id));
    add(uint16_t(0x1800 + n), 2, 1, true, false, n == 1 ? 1 : 255);
    add(uint16_t(0x1A00 + n), 0, 1, true, false, n <= 1 ? 1 : 0);
    for (uint8_t s = 1; s <= 8; ++s)
      add(uint16_t(0x1A00 + n), s, 4, true, false, (s == 1 && n == 0) ? 0x60410010u : (s == 1 && n == 1) ? 0x60640020u : 0u);
  }
  add(0x2F00, 0, 0, true, false, 0);  // writable string (segmented download)
  add(0x6007, 0, 2, true, false, 1);
  add(0x6040, 0, 2, true, true, 0);
  add(0x6041, 0, 2, false, true, 0);
  add(0x6060, 0, 1, true, true, 0);
  add(0x6061, 0, 1, false, true, 0);
  add(0x6064, 0, 4, false, true, 0);
  add(0x606C, 0, 4, false, true, 0);
  add(0x60FD, 0, 4, false, true, 0);  // digital inputs (CiA 402), SimFaults::digital_inputs
  add(0x6071, 0, 2, true, true, 0);
  add(0x6075, 0, 4, false, false, static_cast<uint32_t>(std::lround(p_.rated_current_a * 1000)));
  add(0x6077, 0, 2, false, true, 0);
  add(0x60C2, 1, 1, true, false, 5);
  add(0x60C2, 2, 1, true, false, static_cast<uint8_t>(-4));
}

SimulatedDrive::Entry* SimulatedDrive::find(uint16_t index, uint8_t sub) {
  for (auto& e : od_)
    if (e.index == index && e.sub == sub) return &e;
  return nullptr;
}
const SimulatedDrive::Entry* SimulatedDrive::find(uint16_t index, uint8_t sub) const {
  for (const auto& e : od_)
    if (e.index == index && e.sub == sub) return &e;
  return nullptr;
}

uint32_t SimulatedDrive::od_value(uint16_t index, uint8_t sub) const {
  if (is_live(index)) return live_value(index);
  const Entry* e = find(index, sub);
  return e ? e->value : 0;
}

int32_t SimulatedDrive::position_counts() const {
  return static_cast<int32_t>(std::lround(position_m_ * p_.counts_per_m));
}
int32_t SimulatedDrive::velocity_units() const {
  return static_cast<int32_t>(std::lround(velocity_mps_ * p_.counts_per_m * p_.velocity_units_per_count_s));
}

uint16_t SimulatedDrive::statusword() const {
  uint16_t s = cia402::encode(state_) | cia402::sw::kRemote;
  if (state_ == cia402::State::ReadyToSwitchOn || state_ == cia402::State::SwitchedOn ||
      state_ == cia402::State::OperationEnabled || state_ == cia402::State::QuickStopActive)
    s |= cia402::sw::kVoltageEnabled;
  if (state_ != cia402::State::QuickStopActive && state_ != cia402::State::Fault &&
      state_ != cia402::State::FaultReactionActive && state_ != cia402::State::NotReadyToSwitchOn &&
      state_ != cia402::State::SwitchOnDisabled)
    s |= cia402::sw::kQuickStop;
  if (faults_.power_stage_lost) s &= static_cast<uint16_t>(~cia402::sw::kVoltageEnabled);
  return static_cast<uint16_t>(s | faults_.statusword_extra);
}

uint32_t SimulatedDrive::live_value(uint16_t index) const {
  switch (index) {
    case 0x6041: return statusword();
    case 0x6064: return static_cast<uint32_t>(position_counts());
    case 0x606C: return static_cast<uint32_t>(velocity_units());
    case 0x60FD: return faults_.digital_inputs;
    case 0x6061: { const Entry* e = find(0x6060, 0); return e ? e->value : 0; }
    case 0x6077: {
      const bool on = state_ == cia402::State::OperationEnabled;
      return static_cast<uint16_t>(on ? target_torque_ : 0);
    }
  }
  return 0;
}

uint32_t SimulatedDrive::read_object(uint16_t index, uint8_t sub, bool& ok, uint32_t& abort) const {
  ok = false;
  if (is_live(index) && sub == 0) {
    ok = true;
    return live_value(index);
  }
  const Entry* e = find(index, sub);
  if (!e) {
    bool any = false;
    for (const auto& x : od_) any |= x.index == index;
    abort = any ? 0x06090011 : 0x06020000;
    return 0;
  }
  ok = true;
  return e->value;
}

uint32_t SimulatedDrive::write_object(uint16_t index, uint8_t sub, uint32_t v, std::size_t bytes) {
  if (faults_.reject_abort && index == faults_.reject_index && sub == faults_.reject_sub) return faults_.reject_abort;
  Entry* e = find(index, sub);
  if (!e) {
    if (is_live(index)) return 0x06010002;
    bool any = false;
    for (const auto& x : od_) any |= x.index == index;
    return any ? 0x06090011 : 0x06020000;
  }
  if (!e->writable) return 0x06010002;
  if (e->bytes != 0 && bytes != e->bytes) return bytes > e->bytes ? 0x06070012 : 0x06070013;
  if (is_mapping(index)) {
    // Remapping only in pre-operational, with the PDO invalid and sub0 = 0
    // first (CiA 301 §7.4.8.2 / §7.5.2.36). Drives in the field answer
    // 0x06040041 to a remap outside pre-operational.
    if (nmt_ != NmtState::PreOperational) return 0x06040041;
    const uint16_t comm = static_cast<uint16_t>(index - 0x200);  // 0x1600 -> 0x1400, 0x1A00 -> 0x1800
    const Entry* cob_e = find(comm, 1);
    if (cob_e && !(cob_e->value & kInvalid)) return 0x08000022;
    if (sub == 0) {
      if (v > 8) return 0x06090031;
      int bits = 0;
      for (uint8_t s = 1; s <= v; ++s) bits += find(index, s)->value & 0xFF;
      if (bits > 64) return 0x06040042;
    } else {
      if (find(index, 0)->value != 0) return 0x08000022;
      const uint16_t oi = uint16_t(v >> 16);
      const uint8_t os = uint8_t(v >> 8);
      const uint8_t ob = uint8_t(v);
      bool mappable = false;
      uint8_t size = 0;
      if (const Entry* o = find(oi, os)) { mappable = o->mappable; size = o->bytes; }
      const bool rx = index < 0x1A00;
      if (rx && (oi == 0x6041 || oi == 0x6064 || oi == 0x606C || oi == 0x60FD)) mappable = false;
      if (!rx && (oi == 0x6040 || oi == 0x6071)) mappable = false;
      if (!mappable || ob != size * 8) return 0x06040041;
    }
  }
  if (index == 0x6060 && v != 8 && v != 9 && v != 10) return 0x06090030;
  if ((index >= 0x1400 && index <= 0x1403) || (index >= 0x1800 && index <= 0x1803)) {
    if (sub == 1 && (v & 0x7FF) != (e->value & 0x7FF) && !(e->value & kInvalid) && !(v & kInvalid))
      return 0x06090030;  // change the COB-ID only while invalid
  }
  e->value = v;
  if (index == 0x6040) apply_controlword(static_cast<uint16_t>(v));
  if (index == 0x6071) target_torque_ = static_cast<int16_t>(v);
  if (index == 0x1016) master_hb_last_us_ = -1;  // re-armed: monitoring starts at the next heartbeat
  return 0;
}

void SimulatedDrive::reset_application() {
  for (auto& e : od_)
    if (e.index >= 0x2000) e.value = e.initial;
  state_ = cia402::State::NotReadyToSwitchOn;
  controlword_ = prev_controlword_ = 0;
  target_torque_ = 0;
  fault_pending_ = false;
  reset_communication();
  if (Entry* e = find(0x1001, 0)) e->value = 0;
  if (Entry* e = find(0x1002, 0)) e->value = 0;
}

void SimulatedDrive::reset_communication() {
  for (auto& e : od_)
    if (e.index >= 0x1000 && e.index < 0x2000 && e.index != 0x1001 && e.index != 0x1002) e.value = e.initial;
  for (auto& f : rpdo_fresh_) f = false;
  last_sync_us_ = -1;
  master_hb_last_us_ = -1;
  sdo_op_ = 0;
}

void SimulatedDrive::boot(int64_t now, FrameBuffer& tx) {
  booted_ = true;
  boot_at_us_ = -1;
  nmt_ = NmtState::PreOperational;
  if (state_ == cia402::State::NotReadyToSwitchOn) state_ = cia402::State::SwitchOnDisabled;  // transition 1
  tx.push(make_frame(cob::heartbeat(p_.node_id), {0x00}));  // boot-up message, CiA 301 §7.2.8.3.2.4
  const Entry* hb = find(0x1017, 0);
  next_heartbeat_us_ = now + (hb && hb->value ? int64_t(hb->value) * 1000 : 0);
}

void SimulatedDrive::power_cycle(int64_t now, int64_t off_us) {
  powered_ = false;
  booted_ = false;
  nmt_ = NmtState::BootUp;
  boot_at_us_ = now + off_us + p_.boot_delay_us;
  reset_application();
  velocity_mps_ = 0;
}

void SimulatedDrive::apply_controlword(uint16_t cw) {
  prev_controlword_ = controlword_;
  controlword_ = cw;
  step_state_machine();
}

void SimulatedDrive::step_state_machine() {
  const auto before = state_;
  // A persisting cause keeps the drive in Fault whatever the controlword.
  const bool cause = faults_.fault_persists && (state_ == cia402::State::Fault || state_ == cia402::State::FaultReactionActive);
  auto st = cia402::drive_step(state_, controlword_, prev_controlword_, fault_pending_ || cause);
  state_ = st.state;
  if (fault_pending_) {  // fault reaction is immediate in the simulation (13 then 14)
    state_ = cia402::drive_step(state_, controlword_, prev_controlword_, true).state;
    fault_pending_ = false;
  }
  if (before == cia402::State::Fault && state_ == cia402::State::SwitchOnDisabled) {
    ++fault_resets_;
    if (Entry* e = find(0x1001, 0)) e->value = 0;
    if (Entry* e = find(0x1002, 0)) e->value = 0;
    reset_emcy_pending_ = true;  // EMCY 0x0000 "error reset"
  }
  apply_power_loss(before);
  // Only rising edges count: remember the bit so a held bit 7 does nothing.
  prev_controlword_ = controlword_;
}

void SimulatedDrive::apply_power_loss(cia402::State before) {
  using S = cia402::State;
  if (!faults_.power_stage_lost) return;
  const bool energised = state_ == S::SwitchedOn || state_ == S::OperationEnabled || state_ == S::QuickStopActive;
  if (!energised) return;
  if (faults_.power_loss_state == S::OperationEnabled) {
    // Keeps an energised state it already had (bit 4 off), but cannot enter
    // one: transitions 3, 4, 16 need high voltage.
    if (state_ != before) state_ = before;
    return;
  }
  state_ = faults_.power_loss_state == S::ReadyToSwitchOn ? S::ReadyToSwitchOn : S::SwitchOnDisabled;
}

void SimulatedDrive::enter_fault(uint16_t code, uint32_t event_status) {
  inject_emcy(code, 0x01, true, event_status);
}

void SimulatedDrive::inject_emcy(uint16_t code, uint8_t reg, bool enters_fault, uint32_t event_status) {
  emcy_pending_ = true;
  pending_emcy_code_ = code;
  emcy_reg_ = reg;
  emcy_mfr_ = event_status;
  if (Entry* e = find(0x1001, 0)) e->value = reg;
  if (Entry* e = find(0x1002, 0)) e->value |= event_status;
  if (enters_fault) {
    fault_pending_ = true;
    step_state_machine();
  }
}

void SimulatedDrive::send_emcy(uint16_t code, uint8_t reg, uint32_t mfr, FrameBuffer& tx) {
  // CiA 301 §7.2.7.3.1: bytes 0-1 error code, byte 2 error register (0x1001), 3-7 manufacturer.
  CanFrame f;
  f.id = cob::emcy(p_.node_id);
  f.dlc = 8;
  put_u16(f.data, code);
  f.data[2] = reg;
  put_u32(f.data + 3, mfr);
  tx.push(f);
}

void SimulatedDrive::integrate(double dt) {
  const bool on = state_ == cia402::State::OperationEnabled && nmt_ == NmtState::Operational && powered_ &&
                  !faults_.power_stage_lost;
  const double motor = on ? target_torque_ / 1000.0 * p_.rated_current_a * p_.force_constant_n_per_a : 0.0;
  applied_force_n_ = motor;
  if (p_.external_plant) return;  // the stage is integrated by the caller (set_plant_state)
  const double f = motor + external_force_n_;
  double remaining = dt;
  while (remaining > 0) {
    const double h = std::min(remaining, 1e-4);
    remaining -= h;
    double a = (f - p_.viscous_nspm * velocity_mps_) / p_.mass_kg;
    if (velocity_mps_ != 0) {
      a -= std::copysign(p_.coulomb_n, velocity_mps_) / p_.mass_kg;
      const double v_new = velocity_mps_ + a * h;
      velocity_mps_ = (v_new * velocity_mps_ < 0) ? 0.0 : v_new;  // friction stops, never reverses
    } else if (std::abs(f) > p_.coulomb_n) {
      velocity_mps_ = (f - std::copysign(p_.coulomb_n, f)) / p_.mass_kg * h;
    }
    position_m_ += velocity_mps_ * h;
  }
}

void SimulatedDrive::on_nmt(const CanFrame& f, int64_t now) {
  if (f.dlc < 2 || (f.data[1] != 0 && f.data[1] != p_.node_id)) return;
  switch (static_cast<NmtCommand>(f.data[0])) {
    case NmtCommand::Start: nmt_ = NmtState::Operational; break;
    case NmtCommand::Stop: nmt_ = NmtState::Stopped; break;
    case NmtCommand::EnterPreOperational: nmt_ = NmtState::PreOperational; break;
    case NmtCommand::ResetNode:
      reset_application();
      booted_ = false;
      nmt_ = NmtState::BootUp;
      boot_at_us_ = now + p_.boot_delay_us;
      break;
    case NmtCommand::ResetCommunication:
      reset_communication();
      booted_ = false;
      nmt_ = NmtState::BootUp;
      boot_at_us_ = now + p_.boot_delay_us / 4;
      break;
  }
  if (nmt_ != NmtState::Operational && state_ == cia402::State::OperationEnabled) {
    // Leaving operational disables the power stage (CiA 402 abort connection, 0x6007).
    fault_pending_ = find(0x6007, 0)->value == 1;
    if (!fault_pending_) state_ = cia402::State::SwitchOnDisabled;
    else step_state_machine();
  }
}

void SimulatedDrive::on_sdo(const CanFrame& f, int64_t now, FrameBuffer& tx) {
  (void)now;
  ++sdo_requests_;
  if (faults_.sdo_silent || f.dlc < 8) return;
  const uint8_t answer_node = faults_.answer_as_node ? faults_.answer_as_node : p_.node_id;
  CanFrame r;
  r.id = cob::sdo_tx(answer_node);
  r.dlc = 8;
  const uint8_t cs = f.data[0];
  const uint16_t index = get_u16(f.data + 1);
  const uint8_t sub = f.data[3];
  auto abort = [&](uint16_t i, uint8_t s, uint32_t code) {
    sdo_op_ = 0;
    tx.push(sdo::abort_frame(r.id, i, s, code));
  };
  const uint8_t ccs = cs >> 5;
  if (cs == sdo::kAbort) {
    sdo_op_ = 0;
    return;
  }
  if (ccs == 1) {  // initiate download
    if (faults_.reject_abort && index == faults_.reject_index && sub == faults_.reject_sub)
      return abort(index, sub, faults_.reject_abort);
    if (cs & 0x02) {  // expedited
      const std::size_t n = (cs & 0x01) ? 4 - ((cs >> 2) & 3) : 4;
      uint32_t v = 0;
      for (std::size_t i = 0; i < n; ++i) v |= uint32_t(f.data[4 + i]) << (8 * i);
      if (index == 0x2F00) {
        user_string_.assign(reinterpret_cast<const char*>(f.data + 4), n);
      } else if (uint32_t a = write_object(index, sub, v, n)) {
        return abort(index, sub, a);
      }
      r.data[0] = 0x60;
      put_u16(r.data + 1, index);
      r.data[3] = sub;
      tx.push(r);
      return;
    }
    if (index != 0x2F00) return abort(index, sub, find(index, sub) ? 0x06070012 : 0x06020000);
    sdo_op_ = 2;
    sdo_toggle_ = false;
    sdo_buf_.clear();
    sdo_index_ = index;
    sdo_sub_ = sub;
    r.data[0] = 0x60;
    put_u16(r.data + 1, index);
    r.data[3] = sub;
    tx.push(r);
    return;
  }
  if (ccs == 0) {  // download segment
    if (sdo_op_ != 2) return abort(sdo_index_, sdo_sub_, 0x05040001);
    const bool t = (cs & 0x10) != 0;
    if (t != sdo_toggle_) return abort(sdo_index_, sdo_sub_, 0x05030000);
    const std::size_t n = 7 - ((cs >> 1) & 7);
    sdo_buf_.append(reinterpret_cast<const char*>(f.data + 1), n);
    r.data[0] = static_cast<uint8_t>(0x20 | (t ? 0x10 : 0));
    sdo_toggle_ = !sdo_toggle_;
    if (cs & 1) {
      user_string_ = sdo_buf_;
      sdo_op_ = 0;
    }
    tx.push(r);
    return;
  }
  if (ccs == 2) {  // initiate upload
    if (faults_.reject_abort && index == faults_.reject_index && sub == faults_.reject_sub)
      return abort(index, sub, faults_.reject_abort);
    put_u16(r.data + 1, index);
    r.data[3] = sub;
    if ((index == 0x1008 || index == 0x2F00) && sub == 0) {
      sdo_buf_ = index == 0x1008 ? p_.device_name : user_string_;
      if (sdo_buf_.size() <= 4) {
        r.data[0] = static_cast<uint8_t>(0x43 | ((4 - sdo_buf_.size()) << 2));
        std::copy(sdo_buf_.begin(), sdo_buf_.end(), r.data + 4);
      } else {
        r.data[0] = 0x41;  // segmented, size indicated
        put_u32(r.data + 4, static_cast<uint32_t>(sdo_buf_.size()));
        sdo_op_ = 1;
        sdo_offset_ = 0;
        sdo_toggle_ = false;
        sdo_index_ = index;
        sdo_sub_ = sub;
      }
      tx.push(r);
      return;
    }
    bool ok = false;
    uint32_t a = 0;
    const uint32_t v = read_object(index, sub, ok, a);
    if (!ok) return abort(index, sub, a);
    const Entry* e = find(index, sub);
    const int bytes = e ? e->bytes : (index == 0x6064 || index == 0x606C || index == 0x60FD) ? 4 : (index == 0x6061 ? 1 : 2);
    r.data[0] = static_cast<uint8_t>(0x43 | ((4 - bytes) << 2));
    put_u32(r.data + 4, v);
    tx.push(r);
    return;
  }
  if (ccs == 3) {  // upload segment
    if (sdo_op_ != 1) return abort(sdo_index_, sdo_sub_, 0x05040001);
    const bool t = (cs & 0x10) != 0;
    if (t != sdo_toggle_) return abort(sdo_index_, sdo_sub_, 0x05030000);
    const std::size_t n = std::min<std::size_t>(7, sdo_buf_.size() - sdo_offset_);
    const bool last = sdo_offset_ + n >= sdo_buf_.size();
    r.data[0] = static_cast<uint8_t>((t ? 0x10 : 0) | ((7 - n) << 1) | (last ? 1 : 0));
    std::copy_n(sdo_buf_.begin() + static_cast<std::ptrdiff_t>(sdo_offset_), n, r.data + 1);
    sdo_offset_ += n;
    sdo_toggle_ = !sdo_toggle_;
    if (last) sdo_op_ = 0;
    tx.push(r);
    return;
  }
  abort(index, sub, 0x05040001);
}

void SimulatedDrive::on_rpdo(int n, const CanFrame& f) {
  const Entry* c = find(uint16_t(0x1400 + n), 1);
  if (!c || (c->value & kInvalid)) return;
  ++rpdo_count_;
  rpdo_buf_[n] = f;
  rpdo_fresh_[n] = true;
  if (find(uint16_t(0x1400 + n), 2)->value >= 254) apply_rpdo(n);  // event driven: act at once
}

void SimulatedDrive::apply_rpdo(int n) {
  rpdo_fresh_[n] = false;
  const CanFrame& f = rpdo_buf_[n];
  const uint32_t count = find(uint16_t(0x1600 + n), 0)->value;
  int byte = 0;
  for (uint8_t s = 1; s <= count; ++s) {
    const uint32_t m = find(uint16_t(0x1600 + n), s)->value;
    const int bytes = int(m & 0xFF) / 8;
    if (byte + bytes > f.dlc) return;  // length error: ignore the PDO (EMCY 0x8210 on real drives)
    uint32_t v = 0;
    for (int i = 0; i < bytes; ++i) v |= uint32_t(f.data[byte + i]) << (8 * i);
    byte += bytes;
    const uint16_t idx = uint16_t(m >> 16);
    if (idx == 0x6040) apply_controlword(static_cast<uint16_t>(v));
    else if (idx == 0x6071) target_torque_ = static_cast<int16_t>(v);
  }
}

void SimulatedDrive::on_sync(int64_t now, FrameBuffer& tx) {
  last_sync_us_ = now;
  ++sync_count_;
  for (int n = 0; n < 4; ++n)
    if (rpdo_fresh_[n]) apply_rpdo(n);
  for (int n = 0; n < 4; ++n) {
    const Entry* c = find(uint16_t(0x1800 + n), 1);
    const uint32_t type = find(uint16_t(0x1800 + n), 2)->value;
    if ((c->value & kInvalid) || type == 0 || type > 240 || sync_count_ % type != 0) continue;
    if (faults_.drop_all_tpdos) continue;
    if (faults_.drop_tpdos > 0) {
      --faults_.drop_tpdos;
      continue;
    }
    CanFrame f;
    f.id = c->value & 0x7FF;
    const uint32_t count = find(uint16_t(0x1A00 + n), 0)->value;
    for (uint8_t s = 1; s <= count; ++s) {
      const uint32_t m = find(uint16_t(0x1A00 + n), s)->value;
      const int bytes = int(m & 0xFF) / 8;
      const uint32_t v = od_value(uint16_t(m >> 16), uint8_t(m >> 8));
      for (int i = 0; i < bytes && f.dlc < 8; ++i) f.data[f.dlc++] = uint8_t(v >> (8 * i));
    }
    if (faults_.tpdo_delay_us > 0) {
      if (n_delayed_ < delayed_.size()) delayed_[n_delayed_++] = Delayed{now + faults_.tpdo_delay_us, f};
      continue;
    }
    tx.push(f);
  }
}

void SimulatedDrive::process(int64_t now, std::span<const CanFrame> rx, FrameBuffer& tx) {
  if (last_now_us_ < 0) {
    if (boot_at_us_ >= 0 && powered_ && !booted_) boot_at_us_ += now;  // first call: boot delay from now
    last_now_us_ = now;
  }
  const double dt = (now - last_now_us_) * 1e-6;
  last_now_us_ = now;
  if (!powered_ && boot_at_us_ >= 0 && now >= boot_at_us_ - p_.boot_delay_us) powered_ = true;
  if (!powered_) return;
  apply_power_loss(state_);  // STO / e-stop: the power stage drops out (no CANopen fault)
  integrate(dt);
  if (!booted_) {
    if (!faults_.never_boot && boot_at_us_ >= 0 && now >= boot_at_us_) boot(now, tx);
    if (!booted_) return;  // initialising: deaf and mute
  }
  for (const CanFrame& f : rx) {
    if (f.is_error() || f.is_rtr()) continue;
    const uint32_t fc = function_code(f.id);
    if (f.id == cob::kNmt) on_nmt(f, now);
    else if (f.id == cob::kSync) {
      if (nmt_ == NmtState::Operational) on_sync(now, tx);
    } else if (f.id == cob::sdo_rx(p_.node_id)) {
      if (nmt_ != NmtState::Stopped) on_sdo(f, now, tx);
    } else if (fc == 0x700) {
      const Entry* c = find(0x1016, 1);
      if (c && c->value && ((c->value >> 16) & 0x7F) == node_of(f.id)) master_hb_last_us_ = now;
    } else if (nmt_ == NmtState::Operational) {
      for (int n = 0; n < 4; ++n)
        if (f.id == cob::rpdo(n, p_.node_id)) on_rpdo(n, f);
    }
    if (!booted_) return;  // reset by NMT
  }
  // Heartbeat consumer (CiA 301 §7.2.8.3.2.2): monitoring starts at the first
  // heartbeat from the producer; a timeout is a heartbeat event.
  const Entry* hbc = find(0x1016, 1);
  const uint32_t hbc_ms = hbc ? (hbc->value & 0xFFFF) : 0;
  if (hbc_ms && master_hb_last_us_ >= 0 && now - master_hb_last_us_ > int64_t(hbc_ms) * 1000) {
    master_hb_last_us_ = -1;
    const uint32_t option = find(0x6007, 0)->value;
    inject_emcy(0x8130, 0x11, option == 1, 0);
    if (option != 1 && state_ == cia402::State::OperationEnabled) state_ = cia402::State::SwitchOnDisabled;
  }
  // SYNC loss: the power stage faults after sync_loss_limit missed periods.
  const uint32_t period_us = find(0x1006, 0)->value;
  if (period_us && p_.sync_loss_limit && state_ == cia402::State::OperationEnabled && last_sync_us_ >= 0 &&
      now - last_sync_us_ > int64_t(period_us) * p_.sync_loss_limit + int64_t(period_us) / 2) {
    enter_fault(0x8100, 0x10);
    last_sync_us_ = -1;
  }
  // Delayed TPDOs whose time has come, oldest first.
  std::size_t keep = 0;
  for (std::size_t i = 0; i < n_delayed_; ++i) {
    if (delayed_[i].at_us <= now) tx.push(delayed_[i].frame);
    else delayed_[keep++] = delayed_[i];
  }
  n_delayed_ = keep;
  if (reset_emcy_pending_) {
    reset_emcy_pending_ = false;
    send_emcy(0x0000, 0x00, 0, tx);
  }
  if (emcy_pending_) {
    emcy_pending_ = false;
    send_emcy(pending_emcy_code_, emcy_reg_, emcy_mfr_, tx);
  }
  const Entry* hb = find(0x1017, 0);
  if (hb && hb->value && !faults_.heartbeat_stopped && now >= next_heartbeat_us_) {
    tx.push(make_frame(cob::heartbeat(p_.node_id), {static_cast<uint8_t>(nmt_)}));
    next_heartbeat_us_ = now + int64_t(hb->value) * 1000;
  }
}

void SimulatedDrive::poll(int64_t now, CanPort& port) {
  CanFrame rx[64];
  const std::size_t n = port.receive(std::span<CanFrame>(rx, 64));
  FrameBuffer tx;
  process(now, std::span<const CanFrame>(rx, n), tx);
  for (const CanFrame& f : tx) port.send(f);
}

}  // namespace manip::canopen
