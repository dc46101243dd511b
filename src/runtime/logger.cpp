#include "manip/runtime/logger.hpp"

#include <cstdint>
#include <chrono>
#include <cstdio>
#include <thread>

#include "manip/common/channels.hpp"
#include "manip/common/errors.hpp"
#include "manip/runtime/messages.hpp"
#include "manip/runtime/rt_thread.hpp"

namespace manip::runtime {
using namespace manip::control;  // the loop's records and codes
Logger::Logger(RecordQueue& queue, int fault_history_cycles, double flush_interval_s)
    : q_(queue),
      ring_(static_cast<std::size_t>(fault_history_cycles > 0 ? fault_history_cycles : 1)),
      flush_interval_s_(flush_interval_s) {}

Logger::~Logger() {
  if (open_) {
    std::string err;
    close(err);
  }
}

bool Logger::open(const std::string& path, const manip::session_t& session, std::string& err, bool force) {
  // LockedOutput decides (O_EXCL, or force without truncation, then flock):
  // no check-then-fopen race, and a second instance on the same path with
  // --force is refused instead of truncating the first one's session. The
  // writer then opens the (now empty, locked by us) file by name.
  try {
    lock_ = LockedOutput::open(path, force);
  } catch (const Error& e) {
    err = e.what();
    return false;
  }
  if (!w_.open(path)) {
    err = w_.error();
    lock_.discard();
    return false;
  }
  open_ = true;
  last_utime_ = session.utime_start;
  if (!w_.write_message(channels::kSession, session.utime_start, session) || !w_.flush()) {
    err = w_.error();
    fail(err);
    return false;
  }
  stats_.events_in_file = events_flushed_ = w_.events_written();
  last_flush_ns_ = monotonic_ns();
  return true;
}

void Logger::discard() {
  if (open_) {
    w_.close();
    open_ = false;
  }
  lock_.discard();
}

void Logger::fail(const std::string& why) {
  if (failed_.load(std::memory_order_relaxed)) return;
  {
    std::lock_guard<std::mutex> lk(mu_);
    error_ = why;
  }
  failed_.store(true, std::memory_order_release);
  std::fprintf(stderr,
               "\nmanip_rt: *** LOG WRITE FAILED: %s ***\n"
               "manip_rt: *** the session is being stopped: motors go to the safe law, no further data is recorded ***\n",
               why.c_str());
  std::fflush(stderr);
}

std::string Logger::error() const {
  std::lock_guard<std::mutex> lk(mu_);
  return error_;
}

LoggerStats Logger::stats() const {
  std::lock_guard<std::mutex> lk(mu_);
  return published_;
}

void Logger::publish_stats() {
  std::lock_guard<std::mutex> lk(mu_);
  published_ = stats_;
}

template <class Msg>
void Logger::write(const char* channel, std::int64_t utime, const Msg& m) {
  if (!open_ || failed_.load(std::memory_order_relaxed)) {
    ++stats_.discarded;
    return;
  }
  // Event timestamps must not go backwards in a log: bus-thread records carry
  // wall-clock times; clamp them to the last loop time.
  if (utime < last_utime_) utime = last_utime_;
  last_utime_ = utime;
  if (!w_.write_message(channel, utime, m)) fail(w_.error());
}

void Logger::handle(const LoopRecord& r) {
  if (const auto* s = std::get_if<manip::state_t>(&r)) {
    if (stats_.last_cycle >= 0 && s->cycle != stats_.last_cycle + 1)
      stats_.missing_cycles += s->cycle - stats_.last_cycle - 1;
    if (stats_.first_cycle < 0) stats_.first_cycle = s->cycle;
    stats_.last_cycle = s->cycle;
    ring_[ring_head_] = *s;
    ring_head_ = (ring_head_ + 1) % ring_.size();
    if (ring_fill_ < ring_.size()) ++ring_fill_;
    ++stats_.states;
    last_fault_flags_ = static_cast<std::uint32_t>(s->fault_flags);
    // Every record of earlier cycles is handled: a backend note of those
    // cycles that no fault record took gets a record of its own.
    if (!notes_.empty()) write_pending_notes(s->cycle);
    write(channels::kState, s->utime, *s);
    if (flush_every_states_ > 0 && ++states_since_flush_ >= flush_every_states_) maybe_flush(true);
  } else if (const auto* e = std::get_if<TrialEventRecord>(&r)) {
    ++stats_.events;
    write(channels::kTrial, e->utime, to_message(*e));
  } else if (const auto* f = std::get_if<FaultRecord>(&r)) {
    ++stats_.events;
    ++stats_.faults;
    manip::fault_t m{};
    m.utime = f->utime;
    m.cycle = f->cycle;
    m.fault_flags = static_cast<std::int32_t>(f->fault_flags);
    m.reason = fault_reason(*f);
    // The backend's own reason (e.g. "can backend: node 1: heartbeat lost
    // (after 152 ms)"), queued by the loop in this cycle's read(), before the
    // supervisor pushed this record: visible now.
    if (tap_ && (f->new_flags & (fault::kBackend | fault::kHardwareEStop))) {
      poll_notes();
      for (auto it = notes_.begin(); it != notes_.end(); ++it) {
        const std::uint32_t bits =
            ((it->status & (backend_status::kDriveFault | backend_status::kBackendError)) ? fault::kBackend : 0u) |
            ((it->status & backend_status::kHwEStopOpen) ? fault::kHardwareEStop : 0u);
        if (it->cycle >= 0 && it->cycle <= f->cycle && (bits & f->new_flags)) {
          m.reason += "; " + it->text;
          ++stats_.backend_notes;
          notes_.erase(it);
          break;
        }
      }
    }
    // History: the last N states, but none already written in an earlier
    // fault's history. Every state is in the log anyway; the history is a
    // convenience copy, and an ESTOP/FAULT_RESET storm (a new latch every
    // few cycles) must not multiply the log (issue 9: 30 000 pairs wrote
    // 5 255 x 400 states, 350 MB in 25 s). Bound: each state at most once.
    m.history.reserve(ring_fill_);
    const std::size_t start = (ring_head_ + ring_.size() - ring_fill_) % ring_.size();
    for (std::size_t i = 0; i < ring_fill_; ++i) {
      const manip::state_t& st = ring_[(start + i) % ring_.size()];
      if (st.cycle > history_until_cycle_) m.history.push_back(st);
    }
    m.n_history = static_cast<std::int32_t>(m.history.size());
    if (!m.history.empty()) history_until_cycle_ = m.history.back().cycle;
    stats_.fault_history_states += m.n_history;
    write(channels::kFault, f->utime, m);
    if (print_faults_) print_fault(m, f->fault_flags);
    if (fault_sink_) fault_sink_(m);
  } else if (const auto* c = std::get_if<CommandResultRecord>(&r)) {
    ++stats_.events;
    write(channels::kCommandStatus, c->utime, to_message(*c));
  }
}

void Logger::print_fault(const manip::fault_t& m, std::uint32_t flags) {
  // At most kLinesPerWindow lines per second on stderr: a storm of faults
  // must not flood the operator's terminal; the rest is summarised.
  constexpr int kLinesPerWindow = 5;
  constexpr std::int64_t kWindowNs = 1'000'000'000;
  const std::int64_t now = monotonic_ns();
  if (now - print_window_ns_ >= kWindowNs) {
    if (suppressed_in_window_ > 0)
      std::fprintf(stderr, "manip_rt: ... %lld more fault records like this (not printed; all are in the log)\n",
                   static_cast<long long>(suppressed_in_window_));
    print_window_ns_ = now;
    printed_in_window_ = 0;
    suppressed_in_window_ = 0;
  }
  if (printed_in_window_ >= kLinesPerWindow) {
    ++suppressed_in_window_;
    ++stats_.faults_not_printed;
    return;
  }
  ++printed_in_window_;
  std::fprintf(stderr, "manip_rt: FAULT at cycle %lld: %s (latched: %s; %d cycles of history logged)\n",
               static_cast<long long>(m.cycle), m.reason.c_str(), fault_names(flags).c_str(), m.n_history);
}

void Logger::poll_notes() {
  if (!tap_) return;
  hardware::BackendFaultNote n;
  while (tap_->next_fault_note(n)) notes_.push_back(std::move(n));
}

void Logger::write_pending_notes(std::int64_t before_cycle) {
  while (!notes_.empty() && notes_.front().cycle < before_cycle) {
    const hardware::BackendFaultNote n = std::move(notes_.front());
    notes_.pop_front();
    manip::fault_t m{};
    m.utime = last_utime_;
    m.cycle = n.cycle;
    m.fault_flags = static_cast<std::int32_t>(last_fault_flags_);
    m.reason = n.text;
    m.n_history = 0;
    ++stats_.events;
    ++stats_.backend_notes;
    write(channels::kFault, m.utime, m);
    if (print_faults_) print_fault(m, last_fault_flags_);
    if (fault_sink_) fault_sink_(m);
  }
}

void Logger::drain_raw() {
  if (!tap_) return;
  // Bounded batches (~4096 x 30 bytes): one event stays small, the logger
  // keeps up with two buses at 2 kHz SYNC (~16 000 frames/s).
  while (tap_->next_raw_batch(raw_, 4096)) {
    raw_.utime = last_utime_;
    stats_.raw_frames += raw_.n;
    ++stats_.raw_batches;
    ++stats_.events;
    stats_.raw_frames_dropped = raw_.dropped_total;
    write(channels::kCanRaw, raw_.utime, raw_);
  }
}

void Logger::handle_aux(const AuxRecord& r) {
  ++stats_.events;
  if (const auto* h = std::get_if<manip::health_t>(&r))
    write(channels::kHealth, h->utime, *h);
  else if (const auto* c = std::get_if<manip::command_status_t>(&r))
    write(channels::kCommandStatus, c->utime, *c);
}

void Logger::maybe_flush(bool force) {
  if (!open_ || failed_.load(std::memory_order_relaxed)) return;
  const std::int64_t now = monotonic_ns();
  if (!force && static_cast<double>(now - last_flush_ns_) * 1e-9 < flush_interval_s_) return;
  last_flush_ns_ = now;
  states_since_flush_ = 0;
  ++stats_.flushes;
  if (!w_.flush())
    fail(w_.error());
  else
    events_flushed_ = w_.events_written();
}

std::int64_t Logger::events_on_disk() const {
  // After a write failure, events still in the stdio buffer never reached the
  // disk: count only what the last successful flush delivered.
  return failed() ? events_flushed_ : w_.events_written();
}

std::size_t Logger::drain() {
  std::size_t n = 0;
  poll_notes();  // before the records: a record's note is queued before the record
  LoopRecord r;
  while (q_.try_pop(r)) {
    handle(r);
    ++n;
    if ((n & 4095) == 0) maybe_flush(false);
  }
  if (aux_) {
    AuxRecord a;
    while (aux_->try_pop(a)) {
      handle_aux(a);
      ++n;
    }
  }
  drain_raw();
  // Notes from outside the loop (shutdown) have no record to join.
  if (!notes_.empty() && notes_.front().cycle < 0) write_pending_notes(0);
  maybe_flush(false);
  stats_.events_in_file = events_on_disk();
  publish_stats();
  return n;
}

void Logger::run(const std::atomic<bool>& stop) {
  for (;;) {
    const bool stopping = stop.load(std::memory_order_acquire);
    const std::size_t n = drain();
    if (stopping && n == 0 && q_.size_approx() == 0) break;
    if (n == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}

bool Logger::close(std::string& err) {
  drain();
  poll_notes();
  write_pending_notes(INT64_MAX);  // whatever no record took
  if (open_) {
    maybe_flush(true);
    const bool failed_before = failed();
    if (!w_.close() && !failed()) fail(w_.error());
    if (!failed_before && !failed()) events_flushed_ = w_.events_written();
    stats_.events_in_file = events_on_disk();
    open_ = false;
    lock_ = LockedOutput();  // the writer closed its stream; release the lock
  }
  if (suppressed_in_window_ > 0) {
    std::fprintf(stderr, "manip_rt: ... %lld more fault records like this (not printed; all are in the log)\n",
                 static_cast<long long>(suppressed_in_window_));
    suppressed_in_window_ = 0;
  }
  publish_stats();
  if (failed()) {
    err = error();
    return false;
  }
  return true;
}

}  // namespace manip::runtime
