#pragma once
// The logger thread: drains the loop's record queue into an LCM event log
// (logging::EventLogWriter): session_t first, then every cycle's state_t on
// MANIP_STATE, trial events on MANIP_TRIAL, fault records on MANIP_FAULT,
// command results on MANIP_COMMAND_STATUS, and what the bus thread hands over
// (health_t, bus-side command rejections). Flushed every flush_interval_s.
//
// Gaps: the loop counts every state it could not enqueue (ControllerStatus::
// log_drops); the logger checks the cycle counter and counts missing cycles;
// both are summarised. Fault records: the logger keeps a ring of the last N
// states (it receives every state in order through the same queue as the fault
// notice), so fault_t.history costs the loop nothing.
//
// Write failure (e.g. disk full): failed() turns true (the loop sees it and
// stops the session with the safe law), the error is printed loudly on stderr
// once, and the remaining records are drained and discarded (counted).
#include <atomic>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <string>
#include <variant>
#include <vector>

#include "manip/command_status_t.hpp"
#include "manip/common/output_file.hpp"
#include "manip/control/records.hpp"
#include "manip/runtime/spsc_queue.hpp"
#include "manip/fault_t.hpp"
#include "manip/can_frames_t.hpp"
#include "manip/hardware/backend.hpp"
#include "manip/health_t.hpp"
#include "manip/logging/event_log.hpp"
#include "manip/session_t.hpp"
#include "manip/state_t.hpp"

namespace manip::runtime {

using AuxRecord = std::variant<manip::health_t, manip::command_status_t>;
using AuxQueue = SpscQueue<AuxRecord>;  // bus thread -> logger (both non-real-time)

struct LoggerStats {
  std::int64_t states{0};
  std::int64_t events{0};  // everything but states
  std::int64_t faults{0};
  std::int64_t first_cycle{-1}, last_cycle{-1};
  std::int64_t missing_cycles{0};    // gaps in the cycle counter seen by the logger
  std::int64_t discarded{0};         // records drained but not written after a failure
  std::int64_t flushes{0};
  std::int64_t events_in_file{0};    // events that reached the file (session message included): after a
                                     // write failure, only those of the last successful flush
  std::int64_t fault_history_states{0};  // states written inside fault_t.history (each state at most once)
  std::int64_t faults_not_printed{0};    // fault lines on stderr suppressed by the rate limit
  std::int64_t backend_notes{0};         // backend fault texts logged (merged into a fault record or on their own)
  std::int64_t raw_frames{0};            // raw CAN frames written on MANIP_CAN_RAW
  std::int64_t raw_batches{0};
  std::int64_t raw_frames_dropped{0};    // lost in the backend's queue (can_frames_t.dropped_total)
};

class Logger {
 public:
  Logger(RecordQueue& queue, int fault_history_cycles, double flush_interval_s);
  ~Logger();
  Logger(const Logger&) = delete;
  Logger& operator=(const Logger&) = delete;

  // Creates the file (common/output_file.hpp LockedOutput: O_EXCL, or with
  // `force` without truncating a file another instance holds; flock for the
  // whole session) and writes the session message. False + err if that fails
  // (err names the path: exists, in use, cannot create).
  bool open(const std::string& path, const manip::session_t& session, std::string& err, bool force = false);
  // A start that failed after open(): remove the file this logger created, so
  // no stub blocks the rerun.
  void discard();
  // Flush every n states as well as every flush_interval_s (an as-fast-as-
  // possible run produces many cycles per second: a kill -9 then loses at
  // most n cycles plus the queue). 0 = wall-clock only.
  void set_flush_every_cycles(std::int64_t n) { flush_every_states_ = n; }
  void set_aux_queue(AuxQueue* q) { aux_ = q; }
  // Called (logger thread) with every fault record written, e.g. to publish it.
  void set_fault_sink(std::function<void(const manip::fault_t&)> sink) { fault_sink_ = std::move(sink); }
  // Also print each fault record on stderr (the operator must see it).
  void set_print_faults(bool on) { print_faults_ = on; }
  // The backend's non-real-time side (hardware::Backend::log_tap()): its
  // fault texts go into the fault_t record the supervisor raised in the same
  // cycle (reason + "; " + text), or into a fault_t of their own (n_history
  // 0) when the supervisor raised none (already latched, or at shutdown);
  // raw CAN frames go on MANIP_CAN_RAW in batches. nullptr = none.
  void set_backend_tap(hardware::BackendLogTap* tap) { tap_ = tap; }

  // Process everything available now; returns the number of records handled.
  std::size_t drain();
  // Thread body: drain, flush periodically, sleep briefly when idle; returns
  // once `stop` is set and the queue is empty.
  void run(const std::atomic<bool>& stop);
  // Drain, flush and close. False + err if anything failed during the session.
  bool close(std::string& err);

  [[nodiscard]] const std::atomic<bool>& failed_flag() const { return failed_; }
  [[nodiscard]] bool failed() const { return failed_.load(std::memory_order_acquire); }
  [[nodiscard]] std::string error() const;
  [[nodiscard]] LoggerStats stats() const;

 private:
  void handle(const control::LoopRecord& r);
  void handle_aux(const AuxRecord& r);
  template <class Msg>
  void write(const char* channel, std::int64_t utime, const Msg& m);
  void fail(const std::string& why);
  void maybe_flush(bool force);
  [[nodiscard]] std::int64_t events_on_disk() const;
  void publish_stats();
  void print_fault(const manip::fault_t& m, std::uint32_t flags);
  void poll_notes();
  void write_pending_notes(std::int64_t before_cycle);
  void drain_raw();

  RecordQueue& q_;
  AuxQueue* aux_{nullptr};
  logging::EventLogWriter w_;
  LockedOutput lock_;  // holds the flock (and the right to discard) for the session
  bool open_{false};
  std::int64_t flush_every_states_{0};
  std::int64_t states_since_flush_{0};
  std::int64_t events_flushed_{0};     // events_written() at the last successful flush
  std::int64_t history_until_cycle_{-1};  // newest state already written in a fault history
  std::int64_t print_window_ns_{0};
  int printed_in_window_{0};
  std::int64_t suppressed_in_window_{0};
  std::vector<manip::state_t> ring_;
  std::size_t ring_head_{0}, ring_fill_{0};
  double flush_interval_s_;
  std::int64_t last_flush_ns_{0};
  std::function<void(const manip::fault_t&)> fault_sink_;
  bool print_faults_{true};
  std::atomic<bool> failed_{false};
  mutable std::mutex mu_;  // guards error_ and published_ for readers in other threads
  std::string error_;
  LoggerStats stats_{};      // logger thread only
  LoggerStats published_{};  // copy for other threads
  std::int64_t last_utime_{0};
  hardware::BackendLogTap* tap_{nullptr};
  std::deque<hardware::BackendFaultNote> notes_;
  std::uint32_t last_fault_flags_{0};  // of the newest state handled
  manip::can_frames_t raw_{};
};

}  // namespace manip::runtime
