#include "manip/canopen/cia402.hpp"

namespace manip::canopen::cia402 {

const char* to_string(State s) {
  switch (s) {
    case State::NotReadyToSwitchOn: return "Not ready to switch on";
    case State::SwitchOnDisabled: return "Switch on disabled";
    case State::ReadyToSwitchOn: return "Ready to switch on";
    case State::SwitchedOn: return "Switched on";
    case State::OperationEnabled: return "Operation enabled";
    case State::QuickStopActive: return "Quick stop active";
    case State::FaultReactionActive: return "Fault reaction active";
    case State::Fault: return "Fault";
  }
  return "?";
}

State decode(uint16_t s) {
  if ((s & 0x4F) == 0x00) return State::NotReadyToSwitchOn;
  if ((s & 0x4F) == 0x40) return State::SwitchOnDisabled;
  if ((s & 0x6F) == 0x21) return State::ReadyToSwitchOn;
  if ((s & 0x6F) == 0x23) return State::SwitchedOn;
  if ((s & 0x6F) == 0x27) return State::OperationEnabled;
  if ((s & 0x6F) == 0x07) return State::QuickStopActive;
  if ((s & 0x4F) == 0x0F) return State::FaultReactionActive;
  if ((s & 0x4F) == 0x08) return State::Fault;
  // Undefined bit patterns: treat as fault so nothing is enabled on garbage.
  return State::Fault;
}

uint16_t encode(State s) {
  switch (s) {
    case State::NotReadyToSwitchOn: return 0x0000;
    case State::SwitchOnDisabled: return 0x0040;
    case State::ReadyToSwitchOn: return 0x0021;
    case State::SwitchedOn: return 0x0023;
    case State::OperationEnabled: return 0x0027;
    case State::QuickStopActive: return 0x0007;
    case State::FaultReactionActive: return 0x000F;
    case State::Fault: return 0x0008;
  }
  return 0x0008;
}

MasterStep master_step(uint16_t statusword, Target target, bool fault_reset_requested,
                       uint16_t previous_controlword) {
  const State s = decode(statusword);
  const bool enable = target == Target::OperationEnabled;
  switch (s) {
    case State::Fault:
      if (!fault_reset_requested) return {cw::kDisableVoltage, -1};
      if (previous_controlword & cw::kFaultResetBit) return {cw::kDisableVoltage, -1};  // edge prep
      return {cw::kFaultResetBit, 15};
    case State::FaultReactionActive:  // 14 is automatic
    case State::NotReadyToSwitchOn:   // 1 is automatic
      return {cw::kDisableVoltage, -1};
    case State::SwitchOnDisabled:
      return enable ? MasterStep{cw::kShutdown, 2} : MasterStep{cw::kDisableVoltage, -1};
    case State::ReadyToSwitchOn:
      return enable ? MasterStep{cw::kSwitchOn, 3} : MasterStep{cw::kDisableVoltage, 7};
    case State::SwitchedOn:
      return enable ? MasterStep{cw::kEnableOperation, 4} : MasterStep{cw::kDisableVoltage, 10};
    case State::OperationEnabled:
      if (enable) return {cw::kEnableOperation, -1};
      if (target == Target::QuickStop) return {cw::kQuickStop, 11};
      return {cw::kDisableVoltage, 9};
    case State::QuickStopActive:
      return {cw::kDisableVoltage, 12};
  }
  return {cw::kDisableVoltage, -1};
}

namespace {
bool is_disable_voltage(uint16_t c) { return (c & 0x82) == 0x00; }
bool is_quick_stop(uint16_t c) { return (c & 0x86) == 0x02; }
bool is_shutdown(uint16_t c) { return (c & 0x87) == 0x06; }
bool is_switch_on(uint16_t c) { return (c & 0x8F) == 0x07; }
bool is_enable_operation(uint16_t c) { return (c & 0x8F) == 0x0F; }
}  // namespace

DriveStep drive_step(State s, uint16_t c, uint16_t prev, bool fault_condition) {
  if (fault_condition) {
    if (s == State::FaultReactionActive) return {State::Fault, 14};
    if (s == State::Fault) return {State::Fault, -1};
    return {State::FaultReactionActive, 13};
  }
  const bool rising_reset = (c & cw::kFaultResetBit) && !(prev & cw::kFaultResetBit);
  switch (s) {
    case State::NotReadyToSwitchOn: return {State::SwitchOnDisabled, 1};
    case State::FaultReactionActive: return {State::Fault, 14};
    case State::Fault:
      if (rising_reset) return {State::SwitchOnDisabled, 15};
      return {State::Fault, -1};
    case State::SwitchOnDisabled:
      if (is_shutdown(c)) return {State::ReadyToSwitchOn, 2};
      break;
    case State::ReadyToSwitchOn:
      if (is_switch_on(c) || is_enable_operation(c)) return {State::SwitchedOn, 3};
      if (is_disable_voltage(c) || is_quick_stop(c)) return {State::SwitchOnDisabled, 7};
      break;
    case State::SwitchedOn:
      if (is_enable_operation(c)) return {State::OperationEnabled, 4};
      if (is_shutdown(c)) return {State::ReadyToSwitchOn, 6};
      if (is_disable_voltage(c) || is_quick_stop(c)) return {State::SwitchOnDisabled, 10};
      break;
    case State::OperationEnabled:
      if (is_switch_on(c)) return {State::SwitchedOn, 5};
      if (is_shutdown(c)) return {State::ReadyToSwitchOn, 8};
      if (is_disable_voltage(c)) return {State::SwitchOnDisabled, 9};
      if (is_quick_stop(c)) return {State::QuickStopActive, 11};
      break;
    case State::QuickStopActive:
      if (is_disable_voltage(c)) return {State::SwitchOnDisabled, 12};
      if (is_enable_operation(c)) return {State::OperationEnabled, 16};
      break;
  }
  return {s, -1};
}

}  // namespace manip::canopen::cia402
