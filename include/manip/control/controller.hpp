#pragma once
// The body of the 4 kHz loop as a plain function of (reading, cycle) ->
// command: Controller::step. No threads, clocks or I/O inside; tests drive it
// cycle by cycle with simulated time. Per cycle:
//   1. up to max_commands_per_cycle commands from the command queue
//   2. safety checks of the reading (and timing, logger health) -> latched faults
//   3. protocol (trial phases, trigger, eq. 22-23 perturbation force)
//   4. admittance (eq. 19-20, exact ZOH) with f_sensor + u_pert + wall force
//   5. PD per stage (+ feed-forward) -> motor force; output checks
//   6. safe law instead whenever the mode requires it (same cycle as the fault)
//   7. drive decimation (commands sent at the drive rate; a safe-law change is
//      sent at once), state_t and events into the queues.
// After construction step() never allocates, locks, prints or does I/O.
#include <atomic>
#include <cstdint>

#include "manip/common/frames.hpp"
#include "manip/control/admittance.hpp"
#include "manip/control/config.hpp"
#include "manip/control/protocol.hpp"
#include "manip/control/records.hpp"
#include "manip/control/safety.hpp"
#include "manip/state_t.hpp"

namespace manip::control {

struct ControllerQueues {
  RecordSink* log{nullptr};          // every state + every event (logger thread)
  RecordSink* bus{nullptr};          // decimated states + every event (publisher thread)
  CommandSource* commands{nullptr};  // validated commands (bus thread)
};

struct ControllerOptions {
  bool stop_when_done{true};   // enter STOPPED when the session is done (one session per process)
  bool stop_on_fault{false};   // enter STOPPED on a fault (unattended runs: no operator to reset)
  std::int64_t max_cycles{0};  // enter STOPPED after this many cycles (0: no limit)
  std::int64_t utime_start_us{0};  // state_t.utime = utime_start + cycle * period
};

// Counters and status readable from any thread (relaxed atomics).
struct ControllerStatus {
  std::atomic<std::int64_t> cycle{-1};
  std::atomic<std::int8_t> mode{static_cast<std::int8_t>(Mode::kInit)};
  std::atomic<std::int8_t> phase{0};
  std::atomic<std::uint32_t> fault_flags{0};
  std::atomic<std::int32_t> trial{-1};
  std::atomic<std::int64_t> log_drops{0};
  std::atomic<std::int64_t> bus_drops{0};
  std::atomic<std::int64_t> commands_accepted{0};
  std::atomic<std::int64_t> commands_rejected{0};
  std::atomic<std::int8_t> stop_reason{0};
  std::atomic<bool> finished{false};  // STOPPED for shutdown_cycles: the loop may end
};

class Controller {
 public:
  Controller(const ControlConfig& cfg, ControllerQueues queues, const ControllerOptions& opt = {});

  // One cycle. `overran`: the previous cycle missed its deadline (from the
  // thread wrapper; false in as-fast-as-possible runs).
  const ActuatorCommand& step(const SensorReading& in, std::int64_t cycle, bool overran = false);

  // Any thread: ask for an orderly stop (zero force for shutdown_cycles, then finished).
  void request_stop(StopReason why = StopReason::kRequested);
  // Logger failure flag (set by the logger thread), checked every cycle.
  void set_logger_failed_flag(const std::atomic<bool>* flag) { logger_failed_ = flag; }

  [[nodiscard]] const ControllerStatus& status() const { return status_; }
  [[nodiscard]] Mode mode() const { return sm_.mode(); }
  [[nodiscard]] bool finished() const { return status_.finished.load(std::memory_order_acquire); }
  [[nodiscard]] const manip::state_t& last_state() const { return state_; }
  [[nodiscard]] const Protocol& protocol() const { return protocol_; }
  [[nodiscard]] const Admittance& admittance() const { return adm_; }
  [[nodiscard]] const SafetyStateMachine& state_machine() const { return sm_; }
  [[nodiscard]] std::uint32_t present_conditions() const { return present_; }
  [[nodiscard]] const ProtocolEvents& events() const { return events_; }  // this cycle's trial events
  [[nodiscard]] std::int64_t utime_of(std::int64_t cycle) const { return opt_.utime_start_us + cycle * period_us_; }
  [[nodiscard]] const ControlConfig& config() const { return cfg_; }

 private:
  void handle_command(const Command& c, const SensorReading& in);
  void raise_faults(std::uint32_t bits, const FaultDetail& d);
  void enter_stopped(StopReason why);
  void push_record(const LoopRecord& r, bool to_bus);

  ControlConfig cfg_;
  ControllerQueues q_;
  ControllerOptions opt_;
  std::int64_t period_us_;
  int drive_decimation_;
  int bus_decimation_;
  WorkspaceToShoulder frame_;
  Admittance adm_;
  PdGains pd_;
  SafetyMonitor monitor_;
  SafetyStateMachine sm_;
  Protocol protocol_;
  const std::atomic<bool>* logger_failed_{nullptr};
  std::atomic<std::int8_t> stop_request_{0};

  // per-cycle scratch
  std::int64_t cycle_{0};
  std::int64_t utime_{0};
  ProtocolEvents events_{};
  std::uint32_t present_{0};
  FaultRecord pending_fault_{};
  bool have_pending_fault_{false};
  Vec2 held_force_{Vec2::Zero()};
  int stopped_cycles_{0};
  ActuatorCommand cmd_{};
  manip::state_t state_{};
  ControllerStatus status_{};
};

}  // namespace manip::control
