#pragma once
// Typed CANopen errors. An Error is a plain value (no strings) so the cyclic
// path can raise one without allocating; describe() builds the text later.
#include <cstdint>
#include <string>

namespace manip::canopen {

enum class ErrorCode : uint8_t {
  None = 0,
  ConfigInvalid,         // configuration rejected before touching the bus
  BusLoadTooHigh,        // worst-case budget above the configured limit
  InterfaceUnavailable,  // socket/interface could not be opened
  BootTimeout,           // no boot-up/heartbeat from a node before the boot deadline
  SdoAbort,              // the drive aborted an SDO transfer (abort code decoded)
  SdoTimeout,            // no SDO answer within the SDO timeout
  SdoProtocol,           // malformed/unexpected SDO answer
  SdoNotAllowed,         // SDO requested during the cyclic phase (never allowed)
  VerifyMismatch,        // read-back differs from the configured value
  UnexpectedNode,        // a frame from a node id that is not configured
  NmtStateWrong,         // node reported an NMT state other than expected
  NodeRebooted,          // boot-up message during a session (power cycle / reset)
  HeartbeatLost,         // node heartbeat older than its consumer time
  TpdoMissing,           // k consecutive SYNC periods without the node's TPDO
  EmcyFault,             // EMCY whose policy is "fault the session"
  EmcyWarning,           // EMCY logged only (not a fault)
  DriveFault,            // CiA 402 statusword reports Fault / Fault reaction active
  BusOff,                // controller bus-off (error frame)
  BusErrorPassive,       // controller error passive (error frame)
  ControllerProblem,     // rx/tx overflow or other controller problem (error frame)
  TxOverflow,            // the transport refused frames
  EnableTimeout,         // CiA 402 did not reach Operation enabled in time
  OperatorStop,          // shutdown/e-stop requested by the operator
  CycleOverrun,          // process() called late: SYNC periods skipped
  FaultResetFailed,      // an operator fault reset (one edge on 0x6040 bit 7) left the drive in Fault
  UncommandedDisable,    // the drive left Operation enabled (or lost 0x6041 bit 4) without the master's command
  EStopChain,            // the backend saw the e-stop chain open (0x60FD input / STO statusword bit)
};

const char* to_string(ErrorCode c);

struct Error {
  ErrorCode code = ErrorCode::None;
  uint8_t node = 0;        // 0 = the bus / the master itself
  uint16_t index = 0;      // object index, for SDO/verify errors
  uint8_t sub = 0;
  uint32_t value = 0;      // abort code, EMCY code, read-back value, expected node...
  uint32_t detail = 0;     // expected value, error register, missed count...
  int64_t time_us = 0;

  explicit operator bool() const { return code != ErrorCode::None; }
};

// CiA 301 §7.2.4.3.17 table 22: SDO abort codes.
const char* sdo_abort_text(uint32_t abort_code);

// CiA 301 §7.2.7.3.1 table 21 / CiA 402 error codes: class text of an EMCY error code.
const char* emcy_code_text(uint16_t code);

// Human-readable one-line description ("node 1: SDO abort 0x06040041 ... at 0x1600:01").
std::string describe(const Error& e);

}  // namespace manip::canopen
