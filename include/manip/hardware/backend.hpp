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
#include <string>

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
