#pragma once
// The hardware-interface boundary: every backend (simulation, CANopen drives)
// looks the same to the controller, so the controller code is identical for
// all of them. Per cycle, in this order (RtCycle does it):
//   read(reading)  -> Controller::step(reading, cycle) -> write(command) if command.send
//   display(cue)   (what the lab's visual feedback shows; only simulations use it)
// read/write/display run in the real-time thread: they must not allocate,
// lock or block beyond the backend's own bus I/O. start/stop are the
// non-real-time lifecycle.
#include <memory>
#include <string>

#include "manip/control/config.hpp"
#include "manip/control/records.hpp"

namespace manip::hardware {

class Backend {
 public:
  virtual ~Backend() = default;
  [[nodiscard]] virtual std::string name() const = 0;
  // Configure and enable; after a successful start read/write are real-time safe.
  virtual bool start(std::string& error) = 0;
  // Zero force and disable the drives. Idempotent; called on every exit path.
  virtual void stop() noexcept = 0;
  // Paced in real time by the caller, or free-running (simulations only).
  [[nodiscard]] virtual bool supports_as_fast_as_possible() const { return false; }

  virtual void read(control::SensorReading& out) = 0;
  virtual void write(const control::ActuatorCommand& cmd) = 0;
  virtual void display(const control::DisplayCue& /*cue*/) {}
};

// Exit codes of manip_rt (documented in --help and docs/controller.md).
namespace exit_code {
inline constexpr int kOk = 0;                 // session complete / stopped / duration reached
inline constexpr int kError = 1;              // unexpected internal error
inline constexpr int kUsage = 2;              // bad command line
inline constexpr int kConfig = 3;             // configuration invalid or unreadable
inline constexpr int kBackendUnavailable = 4; // backend not available (e.g. `can` before its issue) or failed to start
inline constexpr int kRealtime = 5;           // --require-rt and no PREEMPT_RT kernel / no real-time privileges
inline constexpr int kLog = 6;                // log file cannot be created, exists, or writing failed (disk full)
inline constexpr int kFault = 7;              // session ended by a safety fault (unattended run, --exit-on-fault)
inline constexpr int kBus = 8;                // LCM bus cannot be created with the given URL
inline constexpr int kInterrupted = 130;      // SIGINT/SIGTERM: stopped safely, log closed
}  // namespace exit_code

struct BackendResult {
  std::unique_ptr<Backend> backend;
  int exit_code{exit_code::kOk};
  std::string error;
};

// "sim" -> SimBackend with the configured simulated person; "can" -> refused
// (exit_code::kBackendUnavailable) until the CANopen issue lands.
BackendResult make_backend(const std::string& name, const control::RtConfig& cfg);

}  // namespace manip::hardware
