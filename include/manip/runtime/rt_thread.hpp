#pragma once
// The real-time wrapper around the loop body (kept apart from it so the body
// stays a plain function that tests drive with simulated time):
//  - detect_rt(): PREEMPT_RT (/sys/kernel/realtime, uname -v) and privileges
//  - lock_memory(): mlockall(MCL_CURRENT | MCL_FUTURE)
//  - configure_rt_thread(): SCHED_FIFO priority, CPU affinity, pre-faulted stack
//  - run_paced(): clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME) every period,
//    wake-up latency and compute time into TimingStats, overruns counted and
//    handled per policy (catch_up: run late cycles back to back up to
//    max_catch_up_cycles behind, then re-anchor; reanchor: next deadline = now +
//    period). Skipped periods are counted; the cycle counter never skips.
//  - run_as_fast_as_possible(): no sleeping; optional back-pressure so a
//    simulated run never overflows the log queue (deterministic, lossless).
#include <cstdint>
#include <string>
#include <vector>

#include "manip/runtime/config.hpp"
#include "manip/runtime/timing.hpp"

namespace manip::runtime {

// CLOCK_MONOTONIC now [ns]: the one clock of the loop, the logger and the bus.
std::int64_t monotonic_ns();

struct RtCapabilities {
  bool preempt_rt{false};
  std::string kernel_release;  // uname -r
  std::string kernel_version;  // uname -v
  bool is_root{false};
  int rtprio_limit{0};         // RLIMIT_RTPRIO soft limit
  [[nodiscard]] bool can_fifo(int priority) const { return is_root || rtprio_limit >= priority; }
};
RtCapabilities detect_rt();

struct RtThreadOptions {
  int priority{80};
  int cpu{-1};
  std::size_t prefault_stack_bytes{512 * 1024};
};

// mlockall; false + err (with the reason and the fix) on failure.
bool lock_memory(std::string& err);
// Applies SCHED_FIFO + affinity to the calling thread and pre-faults its stack.
// Returns false + err if SCHED_FIFO (or the affinity) could not be set.
bool configure_rt_thread(const RtThreadOptions& o, std::string& err);

// What the paced loop thread does before its first cycle: lock memory
// (mlockall) and configure_rt_thread. False + err when either failed; with
// --require-rt the run then ends before the first cycle (exit code 9), like
// libfranka's RealtimeConfig::kEnforce. Replaceable for tests.
using RtSetup = bool (*)(const RtThreadOptions& o, std::string& err);
bool setup_rt_loop_thread(const RtThreadOptions& o, std::string& err);
void prefault_stack(std::size_t bytes);
// Keeps the calling (non-real-time) thread off `cpu` (the loop's CPU), if
// other CPUs exist. No-op for cpu < 0.
void avoid_cpu(int cpu);

// What the wrapper calls once per cycle. Return false to end the loop.
class CycleBody {
 public:
  virtual ~CycleBody() = default;
  virtual bool run_cycle(std::int64_t cycle, bool overran) = 0;
};

struct PacedOptions {
  std::int64_t period_ns{250000};
  OverrunPolicy policy{OverrunPolicy::kCatchUp};
  int max_catch_up_cycles{4};
};
// Returns the number of cycles run.
std::int64_t run_paced(CycleBody& body, const PacedOptions& o, TimingStats& stats);

// Back-pressure predicate for as-fast-as-possible runs: true = wait (yield).
class Backpressure {
 public:
  virtual ~Backpressure() = default;
  virtual bool must_wait() const = 0;
};
std::int64_t run_as_fast_as_possible(CycleBody& body, TimingStats& stats, const Backpressure* bp);

}  // namespace manip::runtime
