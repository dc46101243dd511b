#pragma once
// CiA 402 (IEC 61800-7-201) power drive state machine, both sides, as pure
// functions. Transition numbers are those of CiA 402-2 §6.3 figure "state
// machine" (0..16). Controlword 0x6040, statusword 0x6041.
#include <cstdint>

namespace manip::canopen::cia402 {

enum class State : uint8_t {
  NotReadyToSwitchOn,
  SwitchOnDisabled,
  ReadyToSwitchOn,
  SwitchedOn,
  OperationEnabled,
  QuickStopActive,
  FaultReactionActive,
  Fault,
};
const char* to_string(State s);

// Controlword commands (CiA 402-2 table "device control commands").
namespace cw {
constexpr uint16_t kDisableVoltage = 0x0000;
constexpr uint16_t kQuickStop = 0x0002;
constexpr uint16_t kShutdown = 0x0006;
constexpr uint16_t kSwitchOn = 0x0007;          // also "disable operation"
constexpr uint16_t kEnableOperation = 0x000F;
constexpr uint16_t kFaultResetBit = 0x0080;     // acts on the rising edge only
}  // namespace cw

// Statusword bits (CiA 402-2 §6.3.2 table "statusword").
namespace sw {
constexpr uint16_t kReadyToSwitchOn = 1u << 0;
constexpr uint16_t kSwitchedOn = 1u << 1;
constexpr uint16_t kOperationEnabled = 1u << 2;
constexpr uint16_t kFault = 1u << 3;
constexpr uint16_t kVoltageEnabled = 1u << 4;
constexpr uint16_t kQuickStop = 1u << 5;  // 0 = quick stop active
constexpr uint16_t kSwitchOnDisabled = 1u << 6;
constexpr uint16_t kWarning = 1u << 7;
constexpr uint16_t kRemote = 1u << 9;
constexpr uint16_t kTargetReached = 1u << 10;
}  // namespace sw

// Statusword -> state with the masks of CiA 402-2 table 30 (0x4F / 0x6F).
State decode(uint16_t statusword);
// State -> the state bits of a statusword (other bits zero).
uint16_t encode(State s);

enum class Target : uint8_t { Disabled, OperationEnabled, QuickStop };

struct MasterStep {
  uint16_t controlword = 0;
  int transition = -1;  // transition this controlword requests, -1 = none (hold / automatic)
};

// Master side: the controlword to send next, from the last statusword, the
// wanted target state, an operator fault-reset request, and the controlword
// sent last. Fault reset is only ever produced on operator request and as a
// rising edge of bit 7 (transition 15): if bit 7 was already high it first
// sends it low. Never resets a fault by itself.
MasterStep master_step(uint16_t statusword, Target target, bool fault_reset_requested,
                       uint16_t previous_controlword);

struct DriveStep {
  State state;
  int transition = -1;
};

// Drive side (used by the simulated drive): the state after receiving
// `controlword` (previous one `previous_controlword`) in `state`. A present
// fault condition takes any state to Fault reaction active (13) then Fault
// (14); fault reset (15) needs a rising edge of bit 7 and no fault condition.
DriveStep drive_step(State state, uint16_t controlword, uint16_t previous_controlword,
                     bool fault_condition);

}  // namespace manip::canopen::cia402
