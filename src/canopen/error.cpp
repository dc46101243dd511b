#include "manip/canopen/error.hpp"

#include <cstdarg>
#include <cstdio>

#include "manip/canopen/cia402.hpp"
#include "manip/canopen/frame.hpp"

namespace manip::canopen {

const char* to_string(NmtState s) {
  switch (s) {
    case NmtState::BootUp: return "boot-up";
    case NmtState::Stopped: return "stopped";
    case NmtState::Operational: return "operational";
    case NmtState::PreOperational: return "pre-operational";
    default: return "unknown";
  }
}

const char* to_string(ErrorCode c) {
  switch (c) {
    case ErrorCode::None: return "no error";
    case ErrorCode::ConfigInvalid: return "configuration invalid";
    case ErrorCode::BusLoadTooHigh: return "worst-case bus load above the limit";
    case ErrorCode::InterfaceUnavailable: return "CAN interface unavailable";
    case ErrorCode::BootTimeout: return "node never booted (no boot-up/heartbeat before the boot deadline)";
    case ErrorCode::SdoAbort: return "SDO aborted by the drive";
    case ErrorCode::SdoTimeout: return "SDO timeout (no answer)";
    case ErrorCode::SdoProtocol: return "SDO protocol error (unexpected answer)";
    case ErrorCode::SdoNotAllowed: return "SDO refused: not allowed in the cyclic phase";
    case ErrorCode::VerifyMismatch: return "read-back differs from the configuration";
    case ErrorCode::UnexpectedNode: return "frame from an unexpected node id";
    case ErrorCode::NmtStateWrong: return "node in an unexpected NMT state";
    case ErrorCode::NodeRebooted: return "node rebooted during the session (boot-up seen)";
    case ErrorCode::HeartbeatLost: return "heartbeat lost";
    case ErrorCode::TpdoMissing: return "TPDOs missing for consecutive SYNC periods";
    case ErrorCode::EmcyFault: return "EMCY (faults the session)";
    case ErrorCode::EmcyWarning: return "EMCY (warning)";
    case ErrorCode::DriveFault: return "drive in CiA 402 Fault";
    case ErrorCode::BusOff: return "CAN controller bus-off";
    case ErrorCode::BusErrorPassive: return "CAN controller error passive";
    case ErrorCode::ControllerProblem: return "CAN controller problem";
    case ErrorCode::TxOverflow: return "transmit queue overflow";
    case ErrorCode::EnableTimeout: return "drive did not reach Operation enabled in time";
    case ErrorCode::OperatorStop: return "stopped by the operator";
    case ErrorCode::CycleOverrun: return "control cycle late: SYNC periods skipped";
    case ErrorCode::FaultResetFailed: return "fault reset did not clear the drive fault (cause still present?)";
    case ErrorCode::UncommandedDisable:
      return "drive left Operation enabled without a command from the master (e-stop chain / STO / power stage "
             "supply lost, quick stop, or an unexpected state)";
    case ErrorCode::EStopChain: return "e-stop chain open";
  }
  return "?";
}

const char* sdo_abort_text(uint32_t a) {
  switch (a) {
    case 0x05030000: return "toggle bit not alternated";
    case 0x05040000: return "SDO protocol timed out";
    case 0x05040001: return "client/server command specifier not valid or unknown";
    case 0x05040002: return "invalid block size";
    case 0x05040003: return "invalid sequence number";
    case 0x05040004: return "CRC error";
    case 0x05040005: return "out of memory";
    case 0x06010000: return "unsupported access to an object";
    case 0x06010001: return "attempt to read a write only object";
    case 0x06010002: return "attempt to write a read only object";
    case 0x06020000: return "object does not exist in the object dictionary";
    case 0x06040041: return "object cannot be mapped to the PDO (remap only in pre-operational with the PDO invalid)";
    case 0x06040042: return "the number and length of the objects to be mapped would exceed PDO length";
    case 0x06040043: return "general parameter incompatibility";
    case 0x06040047: return "general internal incompatibility in the device";
    case 0x06060000: return "access failed due to a hardware error";
    case 0x06070010: return "data type does not match, length of service parameter does not match";
    case 0x06070012: return "data type does not match, length of service parameter too high";
    case 0x06070013: return "data type does not match, length of service parameter too low";
    case 0x06090011: return "sub-index does not exist";
    case 0x06090030: return "invalid value for parameter (download only)";
    case 0x06090031: return "value of parameter written too high";
    case 0x06090032: return "value of parameter written too low";
    case 0x06090036: return "maximum value is less than minimum value";
    case 0x060A0023: return "resource not available: SDO connection";
    case 0x08000000: return "general error";
    case 0x08000020: return "data cannot be transferred or stored to the application";
    case 0x08000021: return "data cannot be transferred because of local control";
    case 0x08000022: return "data cannot be transferred because of the present device state";
    case 0x08000023: return "object dictionary dynamic generation fails or no object dictionary is present";
    case 0x08000024: return "no data available";
    default: return "unknown abort code";
  }
}

const char* emcy_code_text(uint16_t c) {
  if (c == 0x0000) return "error reset or no error";
  if (c == 0x8110) return "CAN overrun (objects lost)";
  if (c == 0x8120) return "CAN in error passive mode";
  if (c == 0x8130) return "life guard error or heartbeat error";
  if (c == 0x8140) return "recovered from bus off";
  if (c == 0x8150) return "CAN-ID collision";
  if (c == 0x8210) return "PDO not processed due to length error";
  if (c == 0x8220) return "PDO length exceeded";
  if (c == 0x8250) return "RPDO timeout";
  if (c == 0x8611) return "following error";
  switch (c & 0xFF00) {
    case 0x1000: return "generic error";
    case 0x2100: case 0x2200: case 0x2300: return "current (over-current / short circuit)";
    case 0x3100: return "mains voltage";
    case 0x3200: return "DC link voltage (over/under voltage)";
    case 0x3300: return "output voltage";
    case 0x4100: return "ambient temperature";
    case 0x4200: return "device temperature";
    case 0x4300: return "drive temperature";
    case 0x5000: case 0x5100: case 0x5200: case 0x5300: case 0x5400: case 0x5500: return "device hardware";
    case 0x6000: case 0x6100: case 0x6200: case 0x6300: return "device software";
    case 0x7000: case 0x7100: case 0x7200: case 0x7300: case 0x7400: case 0x7500: case 0x7600: return "additional modules (motor, sensor, encoder)";
    case 0x8000: case 0x8100: case 0x8200: case 0x8300: case 0x8400: case 0x8500: case 0x8600: case 0x8700: return "monitoring";
    case 0x9000: return "external error";
    case 0xF000: return "additional functions";
    case 0xFF00: return "device specific";
    default: return "unknown error code class";
  }
}

namespace {
// Appends to a fixed buffer, truncating; the format attribute lets the
// compiler check every call's arguments against its literal format.
struct Text {
  char buf[320];
  int n = 0;
  [[gnu::format(printf, 2, 3)]] void add(const char* fmt, ...) {
    if (n < 0 || n >= static_cast<int>(sizeof buf)) return;
    std::va_list ap;
    va_start(ap, fmt);
    const int k = std::vsnprintf(buf + n, sizeof buf - static_cast<std::size_t>(n), fmt, ap);
    va_end(ap);
    n = k < 0 ? k : n + k;
  }
};
}  // namespace

std::string describe(const Error& e) {
  Text t;
  const char* what = to_string(e.code);
  if (e.node != 0) t.add("node %u: %s", e.node, what);
  else t.add("bus: %s", what);
  switch (e.code) {
    case ErrorCode::SdoAbort:
      t.add(" at 0x%04X:%02X, abort code 0x%08X (%s)", e.index, e.sub, e.value, sdo_abort_text(e.value));
      break;
    case ErrorCode::SdoTimeout:
    case ErrorCode::SdoProtocol:
    case ErrorCode::SdoNotAllowed:
      t.add(" at 0x%04X:%02X", e.index, e.sub);
      break;
    case ErrorCode::VerifyMismatch:
      t.add(" at 0x%04X:%02X: read 0x%08X, expected 0x%08X", e.index, e.sub, e.value, e.detail);
      break;
    case ErrorCode::UnexpectedNode:
      t.add(" (COB-ID 0x%03X; configured node expected: %u)", e.value, e.detail);
      break;
    case ErrorCode::NmtStateWrong:
      t.add(" (state 0x%02X %s)", e.value, to_string(static_cast<NmtState>(e.value)));
      break;
    case ErrorCode::TpdoMissing:
      t.add(" (%u consecutive periods)", e.detail);
      break;
    case ErrorCode::EmcyFault:
    case ErrorCode::EmcyWarning:
      t.add(" code 0x%04X (%s), error register 0x%02X", e.value, emcy_code_text(static_cast<uint16_t>(e.value)), e.detail);
      break;
    case ErrorCode::DriveFault:
    case ErrorCode::FaultResetFailed:
      t.add(" (statusword 0x%04X)", e.value);
      break;
    case ErrorCode::UncommandedDisable:
      t.add(" (statusword 0x%04X: %s, voltage enabled bit 4 %s); both drives disabled until the operator's FAULT_RESET",
          e.value, cia402::to_string(cia402::decode(static_cast<uint16_t>(e.value))),
          (e.value & cia402::sw::kVoltageEnabled) ? "on" : "off");
      break;
    case ErrorCode::EStopChain:
      t.add("; both drives disabled until the operator's FAULT_RESET");
      break;
    case ErrorCode::BusLoadTooHigh:
      t.add(" (%u.%u %% > limit %u.%u %%)", e.value / 10, e.value % 10, e.detail / 10, e.detail % 10);
      break;
    case ErrorCode::HeartbeatLost:
    case ErrorCode::BootTimeout:
      t.add(" (after %u ms)", e.detail);
      break;
    default: break;
  }
  return std::string(t.buf);
}

}  // namespace manip::canopen
