#include "manip/runtime/session.hpp"

#include <algorithm>
#include <chrono>
#include <csignal>
#include <mutex>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <future>
#include <memory>
#include <sstream>
#include <thread>

#include "manip/runtime/bus.hpp"
#include "manip/runtime/messages.hpp"
#include "manip/runtime/spsc_queue.hpp"
#include "manip/version.hpp"

namespace manip::runtime {
namespace {

using namespace std::chrono_literals;

class QueueBackpressure final : public Backpressure {
 public:
  QueueBackpressure(const RecordQueue* log, std::size_t log_cap, const RecordQueue* bus,
                    std::size_t bus_cap, const std::atomic<bool>* give_up)
      : log_(log), bus_(bus), log_cap_(log_cap), bus_cap_(bus_cap), give_up_(give_up) {}
  bool must_wait() const override {
    // A helper thread that died no longer drains its queue: waiting for it
    // would keep the loop from ever reaching the orderly stop it requested.
    if (give_up_->load(std::memory_order_relaxed)) return false;
    // Leave room for one cycle's worth of records (state + events + command results).
    constexpr std::size_t kMargin = 64;
    if (log_ && log_->size_approx() + kMargin >= log_cap_) return true;
    if (bus_ && bus_->size_approx() + kMargin >= bus_cap_) return true;
    return false;
  }

 private:
  const RecordQueue* log_;
  const RecordQueue* bus_;
  std::size_t log_cap_, bus_cap_;
  const std::atomic<bool>* give_up_;
};

}  // namespace

const char* signal_name(int sig) {
  switch (sig) {
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    case SIGHUP: return "SIGHUP";
    default: return "a signal";
  }
}

std::string RunReport::summary() const {
  std::ostringstream os;
  os << "manip_rt summary: " << cycles << " cycles in " << wall_s << " s wall; stop: "
     << control::stop_reason_name(stop_reason) << "\n";
  os << "  trials: " << trials.started << " started, " << trials.completed << " ended normally ("
     << trials.perturbed_completed << " perturbed), " << trials.aborted << " aborted, " << trials.requeued
     << " re-queued, " << trials.dropped << " dropped; " << trials.onsets << " perturbation onsets; "
     << remaining_slots << " schedule slots left\n";
  os << "  timing: " << timing.summary() << "\n";
  os << "  queues: log drops " << log_drops << ", live-bus drops " << bus_drops << "; commands received on the bus "
     << commands_received << ", accepted " << commands_accepted << ", rejected " << commands_rejected;
  if (bus_packets_dropped > 0)
    os << "; " << bus_packets_dropped
       << " LCM packets dropped by the kernel before manip_rt could read them (socket buffer full: a flood)";
  os << "\n";
  os << "  log: " << log.states << " states (cycles " << log.first_cycle << ".." << log.last_cycle << "), "
     << log.missing_cycles << " missing cycles, " << log.events << " other events, " << log.faults
     << " fault records, " << log.events_in_file << " events in the file";
  if (log.discarded) os << ", " << log.discarded << " records discarded after the write failure";
  if (log.fault_history_states) os << ", " << log.fault_history_states << " states in fault histories";
  if (log.faults_not_printed) os << ", " << log.faults_not_printed << " fault lines not printed (rate limit)";
  if (log.backend_notes) os << ", " << log.backend_notes << " backend fault texts";
  if (log.raw_batches)
    os << "\n  raw CAN frames: " << log.raw_frames << " logged on MANIP_CAN_RAW in " << log.raw_batches << " batches, "
       << log.raw_frames_dropped << " dropped (queue full)";
  os << "\n  faults latched at exit: " << control::fault_names(fault_flags) << "\n";
  return os.str();
}

schema::SessionDescription session_of_run(const RtConfig& cfg, const std::string& source, std::int64_t utime_start_us) {
  schema::SessionDescription d = cfg.session;
  d.software_version = manip::kVersion;
  d.source = source;
  d.utime_start_us = utime_start_us;
  d.config_yaml = cfg.effective_yaml;
  return d;
}

RunReport run_session(const RtConfig& cfg, hardware::Backend& backend, const RunOptions& opt, std::ostream& out) {
  using control::StopReason;
  RunReport rep;
  auto fail = [&](int code, const std::string& msg) {
    backend.shutdown();
    rep.exit_code = code;
    rep.message = msg;
    return rep;
  };

  // --- real-time capability checks (before anything starts) -----------------
  if (!opt.realtime && !backend.supports_as_fast_as_possible())
    return fail(exit_code::kUsage, "backend '" + backend.name() + "' can only run paced in real time (--realtime)");
  if (opt.realtime) {
    const RtCapabilities caps = opt.rt.detect();
    const bool fifo_ok = caps.can_fifo(cfg.loop.priority);
    if (opt.require_rt && (!caps.preempt_rt || !fifo_ok)) {
      std::string why;
      if (!caps.preempt_rt)
        why += "the kernel (" + caps.kernel_release + ", " + caps.kernel_version +
               ") is not PREEMPT_RT (/sys/kernel/realtime absent or 0); ";
      if (!fifo_ok)
        why += "no real-time privileges for SCHED_FIFO priority " + std::to_string(cfg.loop.priority) +
               " (not root, RLIMIT_RTPRIO " + std::to_string(caps.rtprio_limit) +
               "): run as root or grant rtprio in /etc/security/limits.d; ";
      why.resize(why.size() - 2);  // trailing "; "
      return fail(exit_code::kRealtime, "--require-rt: refusing to run: " + why);
    }
    if (!caps.preempt_rt)
      out << "manip_rt: warning: kernel " << caps.kernel_release
          << " is not PREEMPT_RT: wake-up latency is not bounded (use --require-rt to refuse)\n";
    if (!fifo_ok)
      out << "manip_rt: warning: no real-time privileges (not root, RLIMIT_RTPRIO " << caps.rtprio_limit
          << "): the loop runs with SCHED_OTHER and its timing will be unreliable; run as root or grant rtprio "
          << cfg.loop.priority << " (use --require-rt to refuse)\n";
  }

  // --- queues, controller ------------------------------------------------------
  RecordQueue log_q(cfg.loop.log_queue_capacity);
  RecordQueue bus_q(cfg.loop.bus_queue_capacity);
  CommandQueue cmd_q(cfg.loop.command_queue_capacity);
  AuxQueue aux_q(1024);
  const bool want_log = !opt.log_path.empty();
  const std::string url = opt.lcm_url.empty() ? cfg.bus.lcm_url : opt.lcm_url;
  const bool want_bus = url != "none";

  control::ControllerOptions copt;
  copt.stop_when_done = true;
  copt.stop_on_fault = opt.exit_on_fault || !opt.realtime;
  copt.max_cycles = opt.duration_s > 0 ? std::llround(opt.duration_s * cfg.session.sample_rate_hz) : 0;
  copt.utime_start_us = wall_clock_us();
  control::Controller ctl(cfg, {want_log ? &log_q : nullptr, want_bus ? &bus_q : nullptr, &cmd_q}, copt);
  TimingStats timing;

  // --- the loop thread: real-time set-up first, then it waits for "go" --------
  // The set-up (mlockall, SCHED_FIFO, affinity, stack) can only be applied by
  // the thread itself; its result decides, before the log, the bus or the
  // drives are touched, whether a --require-rt run may start at all.
  RtCycle body(backend, ctl);
  std::promise<std::string> setup_promise;  // "" = real-time set-up complete
  std::promise<bool> go_promise;
  std::shared_future<bool> go = go_promise.get_future().share();
  std::atomic<bool> loop_done{false};
  std::atomic<bool> helper_failed{false};  // a helper thread ended by an exception
  std::thread loop_thread([&] {
    std::string err;
    if (opt.realtime) {
      const RtThreadOptions ro{cfg.loop.priority, cfg.loop.cpu, cfg.loop.prefault_stack_bytes};
      if (!opt.rt.setup_thread(ro, err) && err.empty()) err = "real-time set-up failed";
    }
    setup_promise.set_value(err);
    if (go.get()) {
      if (opt.realtime) {
        const PacedOptions po{std::llround(1e9 / cfg.session.sample_rate_hz), cfg.loop.overrun_policy,
                              cfg.loop.max_catch_up_cycles};
        rep.cycles = run_paced(body, po, timing);
      } else {
        // As fast as possible, the loop never runs more than one flush
        // interval (logger.flush_every_cycles) ahead of the logger: a kill -9
        // then loses at most ~2 x flush_every_cycles cycles, not a whole
        // queue (65 536 records, 16 s of loop time).
        const std::size_t log_limit = std::min<std::size_t>(
            cfg.loop.log_queue_capacity,
            static_cast<std::size_t>(std::max<long long>(cfg.logger.flush_every_cycles, 0)) + 64 + 64);
        QueueBackpressure bp(want_log ? &log_q : nullptr, log_limit, want_bus ? &bus_q : nullptr,
                             cfg.loop.bus_queue_capacity, &helper_failed);
        rep.cycles = run_as_fast_as_possible(body, timing, &bp);
      }
    }
    loop_done.store(true, std::memory_order_release);
  });
  bool released = false;
  auto release_loop = [&](bool run) {
    if (released) return;
    released = true;
    go_promise.set_value(run);
    if (!run) loop_thread.join();
  };
  // An exception during set-up (e.g. std::bad_alloc) must not leave the loop
  // thread waiting for "go" (std::terminate on its destruction).
  struct LoopGuard {
    std::function<void()> release;
    ~LoopGuard() { release(); }
  } const loop_guard{[&] {
    release_loop(false);
    if (loop_thread.joinable()) {
      ctl.request_stop(StopReason::kRequested);  // the orderly stop ends a running loop
      loop_thread.join();
    }
  }};
  auto abort_run = [&](int code, const std::string& msg) {
    release_loop(false);
    return fail(code, msg);
  };
  const std::string rt_error = setup_promise.get_future().get();
  if (!rt_error.empty()) {
    if (opt.require_rt)
      return abort_run(exit_code::kRealtime,
                       "--require-rt: the loop thread's real-time set-up failed (" + rt_error + "); no cycle was run");
    out << "manip_rt: warning: " << rt_error << "\n";
  }

  // --- logger --------------------------------------------------------------------
  const manip::session_t session = schema::to_message(session_of_run(cfg, opt.source, copt.utime_start_us));
  Logger logger(log_q, cfg.safety.fault_history_cycles, cfg.logger.flush_interval_s);
  logger.set_flush_every_cycles(cfg.logger.flush_every_cycles);
  if (want_log) {
    // LockedOutput inside: O_EXCL (no check-then-open race), --force without
    // truncating a file another instance holds, flock for the session.
    std::string err;
    if (!logger.open(opt.log_path, session, err, opt.overwrite_log))
      return abort_run(exit_code::kOutput, "cannot create the log: " + err);
    ctl.set_logger_failed_flag(&logger.failed_flag());
  } else if (!opt.quiet) {
    out << "manip_rt: warning: no log file: nothing of this session is recorded\n";
  }
  // A start that fails after the log was created (bus, backend) leaves no
  // stub behind: nothing of a session was recorded, and a stub would block
  // the rerun without --force.
  auto close_log_and_abort = [&](int code, const std::string& msg) {
    if (want_log) logger.discard();
    return abort_run(code, msg);
  };

  // --- live bus ------------------------------------------------------------------
  std::unique_ptr<Bus> bus;
  if (want_bus) {
    bus = std::make_unique<Bus>(cfg, Bus::Links{&bus_q, &cmd_q, &ctl.status(), &timing, want_log ? &aux_q : nullptr});
    std::string err;
    if (!bus->open(url, err)) return close_log_and_abort(exit_code::kBus, err);
    bus->publish_session(session);
    logger.set_fault_sink([b = bus.get()](const manip::fault_t& f) { b->publish_fault(f); });
  }
  logger.set_aux_queue(want_log && want_bus ? &aux_q : nullptr);
  logger.set_backend_tap(want_log ? backend.log_tap() : nullptr);

  // --- backend: configure (slow, may fail; drives disabled), then enable --------
  try {
    backend.configure();
    backend.enable();
  } catch (const Error& e) {
    return close_log_and_abort(exit_code::kBackend, "backend '" + backend.name() + "' failed to start: " + e.what());
  } catch (const std::exception& e) {
    return close_log_and_abort(exit_code::kBackend, "backend '" + backend.name() + "' failed to start: " + e.what());
  }

  // --- helper threads, then the loop -------------------------------------------
  std::atomic<bool> logger_stop{false}, bus_stop{false};
  // No thread body may end in std::terminate (no safe law, no summary, log
  // cut): an exception in a helper thread requests the orderly safe stop,
  // and the run ends with exit 70 and the reason.
  std::mutex internal_mu;
  std::string internal_error;
  auto on_internal = [&](const char* where, const char* what) noexcept {
    try {
      std::lock_guard<std::mutex> lk(internal_mu);
      if (internal_error.empty()) internal_error = std::string(where) + ": " + what;
    } catch (...) {
    }
    helper_failed.store(true, std::memory_order_relaxed);
    ctl.request_stop(StopReason::kRequested);
  };
  auto guarded = [&](const char* where, auto&& fn) noexcept {
    try {
      fn();
    } catch (const std::exception& e) {
      on_internal(where, e.what());
    } catch (...) {
      on_internal(where, "unknown exception");
    }
  };
  std::thread logger_thread;
  const int avoid = opt.realtime ? cfg.loop.cpu : -1;  // keep the helpers off the loop's CPU
  if (want_log)
    logger_thread = std::thread([&] {
      guarded("logger thread", [&] {
        avoid_cpu(avoid);
        logger.run(logger_stop);
      });
    });
  std::thread bus_thread;
  if (bus)
    bus_thread = std::thread([&] {
      guarded("bus thread", [&] {
        avoid_cpu(avoid);
        bus->run(bus_stop);
      });
    });
  const auto wall0 = std::chrono::steady_clock::now();
  release_loop(true);

  // --- supervisor ----------------------------------------------------------------
  bool interrupted = false;
  int signal_no = 0;
  auto next_progress = std::chrono::steady_clock::now() + std::chrono::duration<double>(opt.progress_interval_s);
  while (!loop_done.load(std::memory_order_acquire)) {
    std::this_thread::sleep_for(5ms);
    if (!interrupted && opt.interrupt && opt.interrupt->load()) {
      interrupted = true;
      signal_no = opt.interrupt_signal ? opt.interrupt_signal->load() : 0;
      ctl.request_stop(StopReason::kRequested);
      guarded("supervisor", [&] {
        out << "manip_rt: interrupted by " << signal_name(signal_no)
            << ": stopping safely (zero force, log closed)\n"
            << std::flush;
      });
    }
    if (opt.quiet || opt.progress_interval_s <= 0) continue;
    guarded("supervisor", [&] {
    if (std::chrono::steady_clock::now() >= next_progress) {
      next_progress += std::chrono::duration<double>(opt.progress_interval_s);
      const auto& st = ctl.status();
      const auto cyc = st.cycle.load(std::memory_order_relaxed);
      char buf[200];
      std::snprintf(buf, sizeof buf, "manip_rt: t = %.1f s (loop time), mode %s, trial %d, log drops %lld\n",
                    static_cast<double>(cyc) / cfg.session.sample_rate_hz,
                    control::mode_name(static_cast<control::Mode>(st.mode.load(std::memory_order_relaxed))),
                    st.trial.load(std::memory_order_relaxed),
                    static_cast<long long>(st.log_drops.load(std::memory_order_relaxed)));
      out << buf << std::flush;
    }
    });
  }
  loop_thread.join();
  backend.shutdown();
  rep.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();

  if (bus) rep.bus_packets_dropped = udp_socket_drops();  // before the bus (and its socket) goes
  bus_stop.store(true, std::memory_order_release);
  if (bus_thread.joinable()) bus_thread.join();
  logger_stop.store(true, std::memory_order_release);
  if (logger_thread.joinable()) logger_thread.join();
  std::string log_err;
  bool log_ok = true;
  guarded("closing the log", [&] { log_ok = !want_log || logger.close(log_err); });

  // --- report --------------------------------------------------------------------
  const auto& st = ctl.status();
  rep.stop_reason = static_cast<StopReason>(st.stop_reason.load());
  rep.timing = timing.snapshot();
  rep.latency_histogram = timing.latency_histogram();
  rep.log = logger.stats();
  rep.log_drops = st.log_drops.load();
  rep.bus_drops = st.bus_drops.load();
  rep.commands_accepted = st.commands_accepted.load();
  rep.commands_rejected = st.commands_rejected.load() + (bus ? bus->command_rejects() : 0);
  rep.commands_received = bus ? bus->commands_received() : 0;
  rep.signal = signal_no;
  rep.fault_flags = st.fault_flags.load();
  rep.trials = ctl.protocol().counters();
  rep.remaining_slots = ctl.protocol().remaining();

  std::string internal;
  {
    std::lock_guard<std::mutex> lk(internal_mu);
    internal = internal_error;
  }
  if (!internal.empty()) {
    rep.exit_code = exit_code::kInternal;
    rep.message = "internal error in the " + internal +
                  " (a bug: please report it); the session was stopped safely (safe law, log closed)";
  } else if (!log_ok || rep.stop_reason == StopReason::kLogger) {
    rep.exit_code = exit_code::kOutput;
    rep.message = "log writing failed: " + (log_err.empty() ? logger.error() : log_err) +
                  " (the session was stopped; motors were put in the safe state)";
  } else if (rep.stop_reason == StopReason::kFault) {
    rep.exit_code = exit_code::kFault;
    rep.message = "session ended by a safety fault: " + control::fault_names(rep.fault_flags);
  } else if (interrupted) {
    rep.exit_code = exit_code::kInterrupted;
    rep.message = std::string("interrupted by ") + signal_name(signal_no) + "; stopped safely";
  } else if (rep.fault_flags != 0) {
    // A paced session that reached --duration (or its end) with a fault
    // still latched must not look like a good one.
    rep.exit_code = exit_code::kFault;
    rep.message = std::string(rep.stop_reason == StopReason::kDuration ? "duration reached" : "session ended") +
                  " with a latched safety fault: " + control::fault_names(rep.fault_flags);
  } else {
    rep.exit_code = exit_code::kOk;
    rep.message = rep.stop_reason == StopReason::kDuration ? "duration reached" : "session complete";
  }
  return rep;
}

}  // namespace manip::runtime
