#include "manip/runtime/rt_thread.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/utsname.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <ctime>
#include <fstream>
#include <thread>

namespace manip::runtime {
std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

namespace {

std::int64_t now_ns() { return monotonic_ns(); }

timespec to_timespec(std::int64_t ns) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(ns / 1000000000LL);
  ts.tv_nsec = static_cast<long>(ns % 1000000000LL);
  return ts;
}

void sleep_until(std::int64_t deadline_ns) {
  const timespec ts = to_timespec(deadline_ns);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

}  // namespace

RtCapabilities detect_rt() {
  RtCapabilities c;
  std::ifstream f("/sys/kernel/realtime");
  int v = 0;
  if (f >> v && v == 1) c.preempt_rt = true;
  utsname u{};
  if (uname(&u) == 0) {
    c.kernel_release = u.release;
    c.kernel_version = u.version;
    if (std::strstr(u.version, "PREEMPT_RT") || std::strstr(u.version, "PREEMPT RT")) c.preempt_rt = true;
  }
  c.is_root = geteuid() == 0;
  rlimit rl{};
  if (getrlimit(RLIMIT_RTPRIO, &rl) == 0)
    c.rtprio_limit = rl.rlim_cur == RLIM_INFINITY ? 99 : static_cast<int>(rl.rlim_cur);
  return c;
}

bool lock_memory(std::string& err) {
  if (mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
    err = std::string("mlockall failed (") + std::strerror(errno) +
          "): run as root or raise the memlock limit (ulimit -l unlimited / /etc/security/limits.d)";
    return false;
  }
  return true;
}

void prefault_stack(std::size_t bytes) {
  if (bytes == 0) return;
  // Touch every page of a stack area so later growth does not page-fault.
  constexpr std::size_t kChunk = 64 * 1024;
  volatile unsigned char buf[kChunk];
  for (std::size_t i = 0; i < kChunk; i += 4096) buf[i] = 0;
  if (bytes > kChunk) prefault_stack(bytes - kChunk);
  buf[0] = buf[0];
}

void avoid_cpu(int cpu) {
  if (cpu < 0) return;
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) != 0) return;
  if (!CPU_ISSET(cpu, &set) || CPU_COUNT(&set) < 2) return;
  CPU_CLR(cpu, &set);
  pthread_setaffinity_np(pthread_self(), sizeof set, &set);
}

bool configure_rt_thread(const RtThreadOptions& o, std::string& err) {
  bool ok = true;
  if (o.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(o.cpu, &set);
    if (const int rc = pthread_setaffinity_np(pthread_self(), sizeof set, &set); rc != 0) {
      err += "cannot pin the loop to CPU " + std::to_string(o.cpu) + " (" + std::strerror(rc) + "); ";
      ok = false;
    }
  }
  sched_param sp{};
  sp.sched_priority = o.priority;
  if (const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp); rc != 0) {
    err += "cannot set SCHED_FIFO priority " + std::to_string(o.priority) + " (" + std::strerror(rc) +
           "): run as root, or grant CAP_SYS_NICE, or allow rtprio " + std::to_string(o.priority) +
           " in /etc/security/limits.d";
    ok = false;
  }
  prefault_stack(o.prefault_stack_bytes);
  return ok;
}

bool setup_rt_loop_thread(const RtThreadOptions& o, std::string& err) {
  std::string mlock_err;
  const bool locked = lock_memory(mlock_err);
  const bool fifo = configure_rt_thread(o, err);
  if (!locked) err += (err.empty() ? "" : "; ") + mlock_err;
  return locked && fifo;
}

std::int64_t run_paced(CycleBody& body, const PacedOptions& o, TimingStats& stats) {
  const std::int64_t period = o.period_ns;
  std::int64_t deadline = now_ns() + period;
  std::int64_t cycle = 0;
  bool overran = false;
  for (;;) {
    sleep_until(deadline);
    const std::int64_t wake = now_ns();
    const bool cont = body.run_cycle(cycle, overran);
    const std::int64_t end = now_ns();
    stats.record(wake - deadline, end - wake);
    ++cycle;
    if (!cont) break;
    const std::int64_t next = deadline + period;
    overran = end > next;
    if (overran) stats.add_overrun();
    if (o.policy == OverrunPolicy::kReanchor) {
      if (overran) {
        const std::int64_t behind = (end - deadline) / period;  // whole periods lost
        stats.add_skipped(behind > 0 ? behind - 1 : 0);
        deadline = end + period;
      } else {
        deadline = next;
      }
    } else {
      deadline = next;
      // Too far behind to catch up: re-anchor, counting the skipped periods.
      if (end - deadline > static_cast<std::int64_t>(o.max_catch_up_cycles) * period) {
        const std::int64_t behind = (end - deadline) / period;
        stats.add_skipped(behind);
        deadline += behind * period;
        if (deadline < end) deadline += period;
      }
    }
  }
  return cycle;
}

std::int64_t run_as_fast_as_possible(CycleBody& body, TimingStats& stats, const Backpressure* bp) {
  std::int64_t cycle = 0;
  for (;;) {
    while (bp && bp->must_wait()) std::this_thread::yield();
    const std::int64_t t0 = now_ns();
    const bool cont = body.run_cycle(cycle, false);
    stats.record_compute(now_ns() - t0);
    ++cycle;
    if (!cont) break;
  }
  return cycle;
}

}  // namespace manip::runtime
