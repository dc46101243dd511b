#pragma once
// The hardware-interface boundary: every backend (simulation, CANopen drives)
// looks the same to the controller, so the controller code is identical for
// all of them. Per cycle, in this order (runtime::RtCycle does it):
//   read(reading)  -> Controller::step(reading, cycle) -> write(command) if command.send
//   display(cue)   (what the lab's visual feedback shows; only simulations use it)
// read/write/display run in the real-time thread: they must not allocate,
// lock or block beyond the backend's own bus I/O.
//
// Lifecycle (ros2_control's hardware-interface states, libfranka's split of
// connecting from commanding): a CiA 402 drive must be opened and checked
// (slow, may fail) long before it is switched on, and switched off before the
// bus is closed:
//   Unconfigured --configure()--> Inactive --enable()--> Active
//   Active --disable()--> Inactive;   any --shutdown()--> Finalized
// configure(): open, check, everything that can fail slowly; drives stay
//   disabled. enable(): switch on; afterwards read/write are real-time safe.
// disable() and shutdown() never throw and are idempotent; shutdown() runs on
// every exit path (it disables first when Active). A call out of order is
// refused with BackendStateError and changes nothing.
#include <cstdint>
#include <string>

#include "manip/can_frames_t.hpp"
#include "manip/common/errors.hpp"
#include "manip/control/records.hpp"

namespace manip::hardware {

enum class BackendState { kUnconfigured, kInactive, kActive, kFinalized };
const char* state_name(BackendState s);

// A lifecycle call in the wrong state: a programming error of the caller.
struct BackendStateError : Error {
  explicit BackendStateError(const std::string& what) : Error(exit_code::kInternal, what) {}
};
// configure()/enable() failed (drive not found, bus down, bad parameters).
struct BackendError : Error {
  explicit BackendError(const std::string& what) : Error(exit_code::kBackend, what) {}
};

// A backend's own account of a fault (e.g. the decoded CANopen reason), for
// the session log. The loop only queues a fixed-size record; the text is
// built here, on the logger thread.
struct BackendFaultNote {
  std::int64_t cycle{-1};   // loop cycle whose read() raised it (state_t.cycle); -1 = outside the loop
  std::uint32_t status{0};  // backend_status bits it raised
  std::string text;
};

// What the logger thread takes from a backend (never called by the loop).
class BackendLogTap {
 public:
  virtual ~BackendLogTap() = default;
  // The next fault note, oldest first; false if none.
  virtual bool next_fault_note(BackendFaultNote& out) = 0;
  // Raw bus traffic recorded since the last call, at most max_frames frames,
  // as one message for channels::kCanRaw; false if nothing is waiting.
  virtual bool next_raw_batch(manip::can_frames_t& /*out*/, std::size_t /*max_frames*/) { return false; }
};

class Backend {
 public:
  virtual ~Backend() = default;
  [[nodiscard]] virtual std::string name() const = 0;

  // Throw BackendError on failure (the state is then unchanged).
  void configure();
  void enable();
  // Zero force and disable the drives (Active -> Inactive); no-op otherwise.
  void disable() noexcept;
  // Release everything; idempotent, valid in every state.
  void shutdown() noexcept;
  [[nodiscard]] BackendState state() const { return state_; }

  // Paced in real time by the caller, or free-running (simulations only).
  [[nodiscard]] virtual bool supports_as_fast_as_possible() const { return false; }

  // Active only (not checked: real-time path).
  virtual void read(control::SensorReading& out) = 0;
  virtual void write(const control::ActuatorCommand& cmd) = 0;
  virtual void display(const control::DisplayCue& /*cue*/) {}
  // The safety supervisor accepted the operator's FAULT_RESET in this cycle
  // (runtime::RtCycle calls it, in the loop thread, before write()): the
  // backend acknowledges its own latched faults (CAN: one rising edge of
  // 0x6040 bit 7, then the drives are re-enabled). Real-time safe.
  virtual void request_fault_reset() noexcept {}
  // Non-real-time side for the logger thread; nullptr = nothing to log.
  virtual BackendLogTap* log_tap() noexcept { return nullptr; }

 protected:
  virtual void on_configure() = 0;
  virtual void on_enable() = 0;
  virtual void on_disable() noexcept = 0;
  virtual void on_shutdown() noexcept {}

 private:
  void require(BackendState s, const char* call) const;
  BackendState state_{BackendState::kUnconfigured};
};

}  // namespace manip::hardware
