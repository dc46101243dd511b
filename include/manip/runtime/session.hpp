#pragma once
// One manip_rt session, composed: backend + controller in the loop thread
// (paced with SCHED_FIFO, or as fast as possible for simulations), the logger
// thread, the LCM bus thread, and a supervisor (the caller's thread) that
// watches for signals. apps/manip_rt.cpp is a thin CLI around run_session().
//
//   backend.read -> Controller::step -> backend.write      (loop thread, 4 kHz)
//        records -> SpscQueue -> Logger (file)  /  Bus (live LCM)
//   Bus (commands) -> SpscQueue -> Controller
#include <atomic>
#include <cstdint>
#include <ostream>
#include <string>
#include <vector>

#include "manip/common/exit_codes.hpp"
#include "manip/control/controller.hpp"
#include "manip/control/protocol.hpp"
#include "manip/control/records.hpp"
#include "manip/hardware/backend.hpp"
#include "manip/runtime/config.hpp"
#include "manip/runtime/logger.hpp"
#include "manip/runtime/rt_thread.hpp"
#include "manip/runtime/timing.hpp"

namespace manip::runtime {

// The loop body for the thread wrapper: read -> step -> write -> display.
class RtCycle final : public CycleBody {
 public:
  RtCycle(hardware::Backend& b, control::Controller& c) : b_(b), c_(c) {}
  bool run_cycle(std::int64_t cycle, bool overran) override {
    b_.read(reading_);
    const control::Mode before = c_.mode();
    const control::ActuatorCommand& cmd = c_.step(reading_, cycle, overran);
    // FAULT/ESTOP -> IDLE/PAUSED happens only when the supervisor accepts
    // the operator's FAULT_RESET (SafetyStateMachine::fault_reset): the
    // backend then acknowledges its own latched faults.
    const control::Mode after = c_.mode();
    if ((before == control::Mode::kFault || before == control::Mode::kEStop) &&
        (after == control::Mode::kIdle || after == control::Mode::kPaused))
      b_.request_fault_reset();
    if (cmd.send) b_.write(cmd);
    b_.display(cmd.cue);
    return !c_.finished();
  }
  [[nodiscard]] const control::SensorReading& reading() const { return reading_; }

 private:
  hardware::Backend& b_;
  control::Controller& c_;
  control::SensorReading reading_{};
};

// The real-time environment: detected up front, set up inside the loop
// thread. Tests replace both to exercise the enforcement without root.
struct RtEnvironment {
  RtCapabilities (*detect)(){&detect_rt};
  RtSetup setup_thread{&setup_rt_loop_thread};
};

struct RunOptions {
  std::string log_path;        // "" = no log file (tests only)
  bool overwrite_log{false};
  bool realtime{false};        // paced at the sample rate (SCHED_FIFO); false = as fast as possible
  bool require_rt{false};      // refuse to run without PREEMPT_RT and real-time privileges (exit 9)
  std::string lcm_url;         // "" = config bus.lcm_url; "none" = no live bus
  double duration_s{0.0};      // stop after this much (loop) time; 0 = until the session ends
  bool exit_on_fault{false};   // end the run on a fault (always so when not paced: nobody can reset)
  bool quiet{false};
  double progress_interval_s{10.0};  // progress lines on `out` (0 = none)
  const std::atomic<bool>* interrupt{nullptr};  // set by a signal handler
  const std::atomic<int>* interrupt_signal{nullptr};  // which signal (named in the message), optional
  std::string source{"manip_rt/sim"};
  RtEnvironment rt{};
};

struct RunReport {
  int exit_code{exit_code::kOk};
  std::string message;
  control::StopReason stop_reason{control::StopReason::kNone};
  std::int64_t cycles{0};
  double wall_s{0.0};
  TimingSnapshot timing{};
  std::vector<std::int64_t> latency_histogram;  // 1 us bins, last = over range
  LoggerStats log{};
  std::int64_t log_drops{0}, bus_drops{0};
  std::int64_t commands_accepted{0}, commands_rejected{0};
  std::int64_t commands_received{0};  // on the bus (decodable or not)
  std::int64_t bus_packets_dropped{0};  // kernel drops on the LCM socket (udp_socket_drops)
  int signal{0};                      // the signal that interrupted the run, 0 if none
  std::uint32_t fault_flags{0};
  control::Protocol::Counters trials{};
  int remaining_slots{0};
  [[nodiscard]] std::string summary() const;
};

// "SIGHUP" etc. for messages.
const char* signal_name(int sig);

// The session message of a run: cfg.session with source, start time and the
// effective configuration text filled in.
schema::SessionDescription session_of_run(const RtConfig& cfg, const std::string& source, std::int64_t utime_start_us);

// Configures and enables the backend, runs, and always shuts the backend down.
RunReport run_session(const RtConfig& cfg, hardware::Backend& backend, const RunOptions& opt, std::ostream& out);

}  // namespace manip::runtime
