#include "manip/runtime/bus.hpp"

#include <lcm/lcm-cpp.hpp>

#include <dirent.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <set>

#include "manip/common/channels.hpp"
#include "manip/logging/safe_decode.hpp"
#include "manip/runtime/messages.hpp"
#include "manip/runtime/rt_thread.hpp"

namespace manip::runtime {
using namespace manip::control;  // the loop's records and codes
CommandLimits CommandLimits::from_config(const RtConfig& cfg) {
  CommandLimits l;
  l.frame = cfg.session.frame;
  l.wall_start_m = cfg.safety.wall_start_m;
  l.target_radius_m = cfg.protocol.target_radius_m;
  l.trigger_x2_shoulder_m = cfg.session.perturbation.trigger_x2_shoulder_m;
  l.require_trigger_between = cfg.perturbed_count() > 0;
  return l;
}

Reject validate_command(const manip::command_t& c, const CommandLimits& lim) {
  if (c.kind < manip::command_t::START_SESSION || c.kind > manip::command_t::FAULT_RESET) return Reject::kUnknownKind;
  if (c.kind != manip::command_t::SET_TARGETS) return Reject::kNone;
  const Vec2 s(c.start_shoulder_m[0], c.start_shoulder_m[1]);
  const Vec2 g(c.goal_shoulder_m[0], c.goal_shoulder_m[1]);
  if (!s.allFinite() || !g.allFinite()) return Reject::kNotFinite;
  for (const Vec2& t : {s, g}) {
    const Vec2 w = lim.frame.point_to_workspace(t);
    if (std::abs(w.x()) + lim.target_radius_m > lim.wall_start_m + 1e-9 || std::abs(w.y()) + lim.target_radius_m > lim.wall_start_m + 1e-9)
      return Reject::kOutOfWorkspace;
  }
  if ((g - s).norm() < 2.0 * lim.target_radius_m) return Reject::kTargetsTooClose;
  if (lim.require_trigger_between &&
      !((lim.trigger_x2_shoulder_m - s.y()) * (lim.trigger_x2_shoulder_m - g.y()) < 0.0))
    return Reject::kTriggerNotBetweenTargets;
  return Reject::kNone;
}

std::optional<manip::command_status_t> CommandGate::submit(const void* data, int size, std::int64_t utime_now,
                                                           std::int8_t mode_now) {
  ++received_;
  manip::command_status_t st{};
  st.utime = utime_now;
  st.mode = mode_now;
  st.accepted = false;
  manip::command_t c{};
  // Untrusted bytes (LCM is unauthenticated multicast): the generated decode
  // throws std::length_error on a string length of 0 (issue 9: one 45-byte
  // packet aborted manip_rt). safe_decode walks the layout first and never
  // throws; the answer names what is wrong and where.
  const logging::DecodeResult dr =
      size > 0 ? logging::safe_decode(data, static_cast<std::size_t>(size), c)
               : logging::DecodeResult{logging::DecodeStatus::short_data, 0, size};
  if (!dr) {
    ++rejected_;
    st.seq = -1;
    st.kind = 0;
    st.reason = reject_text(Reject::kUndecodable);
    st.reason += ": ";
    st.reason += size > 0 ? dr.message() : "empty payload";
    return st;
  }
  st.seq = c.seq;
  st.kind = c.kind;
  Reject r = validate_command(c, lim_);
  if (r == Reject::kNone) {
    Command cmd;
    cmd.seq = c.seq;
    cmd.kind = c.kind;
    cmd.start_shoulder_m = Vec2(c.start_shoulder_m[0], c.start_shoulder_m[1]);
    cmd.goal_shoulder_m = Vec2(c.goal_shoulder_m[0], c.goal_shoulder_m[1]);
    if (q_.try_push(cmd)) return std::nullopt;
    r = Reject::kQueueFull;
  }
  ++rejected_;
  st.reason = reject_text(r);
  if (r == Reject::kUnknownKind) {
    st.reason += ' ';
    st.reason += std::to_string(static_cast<int>(c.kind));
  }
  return st;
}

Bus::Bus(const RtConfig& cfg, Links links)
    : cfg_(cfg), links_(links), gate_(*links.to_loop, CommandLimits::from_config(cfg)) {
  cue_.start_shoulder_m = cfg.protocol.start_shoulder_m;
  cue_.goal_shoulder_m = cfg.protocol.goal_shoulder_m;
}

Bus::~Bus() {
  if (lcm_ && sub_) lcm_unsubscribe(lcm_->getUnderlyingLCM(), sub_);
}

bool Bus::open(const std::string& url, std::string& err) {
  lcm_ = std::make_unique<lcm::LCM>(url);
  if (!lcm_->good()) {
    lcm_.reset();
    err = "cannot create LCM with URL '" + url +
          "' (for udpm: is there a multicast route? e.g. `ip route add 224.0.0.0/4 dev lo` for loopback; "
          "or pass --lcm-url none to run without the live bus)";
    return false;
  }
  sub_ = lcm_subscribe(lcm_->getUnderlyingLCM(), channels::kCommand, &Bus::c_on_command, this);
  if (sub_) lcm_subscription_set_queue_capacity(sub_, cfg_.bus.subscription_queue_capacity);
  next_health_ns_ = monotonic_ns();
  return true;
}

template <class Msg>
void Bus::publish(const char* channel, const Msg& m) {
  if (!lcm_) return;
  if (lcm_->publish(channel, &m) != 0) ++publish_errors_;
}

void Bus::publish_session(const manip::session_t& s) {
  publish(channels::kSession, s);
  publish_targets();
}
void Bus::publish_fault(const manip::fault_t& f) { publish(channels::kFault, f); }

void Bus::c_on_command(const _lcm_recv_buf_t* rbuf, const char* /*channel*/, void* self) {
  // No exception may cross liblcm's C frames (that is std::terminate): a
  // command that makes anything here throw (e.g. bad_alloc) is counted as
  // rejected and the bus keeps serving.
  auto* bus = static_cast<Bus*>(self);
  try {
    bus->on_command(rbuf->data, static_cast<int>(rbuf->data_size));
  } catch (...) {
    bus->handler_errors_.fetch_add(1, std::memory_order_relaxed);
  }
}

void Bus::on_command(const void* data, int size) {
  const std::int8_t mode = links_.status ? links_.status->mode.load(std::memory_order_relaxed) : 0;
  auto rejected = gate_.submit(data, size, wall_clock_us(), mode);
  manip::command_t c{};
  if (!rejected && c.decode(data, 0, size) == size && c.kind == manip::command_t::SET_TARGETS) {
    if (pending_targets_.size() >= 256) pending_targets_.pop_front();  // the loop answers every command: bound only
    pending_targets_.push_back(Command{c.seq, c.kind, Vec2(c.start_shoulder_m[0], c.start_shoulder_m[1]),
                                       Vec2(c.goal_shoulder_m[0], c.goal_shoulder_m[1])});
  }
  if (rejected) {
    publish(channels::kCommandStatus, *rejected);
    if (links_.to_logger) links_.to_logger->push_growing(AuxRecord(*rejected));
  }
}

void Bus::drain_loop() {
  if (!links_.from_loop) return;
  LoopRecord r;
  while (links_.from_loop->try_pop(r)) {
    track_targets(r);
    if (const auto* s = std::get_if<manip::state_t>(&r)) {
      publish(channels::kStateLive, *s);
      ++published_states_;
    } else if (const auto* e = std::get_if<TrialEventRecord>(&r)) {
      publish(channels::kTrial, to_message(*e));
    } else if (const auto* c = std::get_if<CommandResultRecord>(&r)) {
      publish(channels::kCommandStatus, to_message(*c));
    }
    // FaultRecord: published with its history by the logger's fault sink.
  }
}

// The display must show a SET_TARGETS the moment the loop applies it, not at the
// next trial START: the loop's answer (CommandResultRecord) says when, the
// command remembered at submission says what.
void Bus::track_targets(const LoopRecord& r) {
  bool changed = false;
  if (const auto* s = std::get_if<manip::state_t>(&r)) {
    cue_cycle_ = s->cycle;
    changed = s->phase != static_cast<std::int8_t>(cue_.phase) || s->trial != cue_.trial;
    cue_.phase = static_cast<Phase>(s->phase);
    cue_.trial = s->trial;
  } else if (const auto* e = std::get_if<TrialEventRecord>(&r)) {
    if (e->kind == manip::trial_event_t::START) {
      changed = e->start_shoulder_m != cue_.start_shoulder_m || e->goal_shoulder_m != cue_.goal_shoulder_m;
      cue_.start_shoulder_m = e->start_shoulder_m;
      cue_.goal_shoulder_m = e->goal_shoulder_m;
    }
  } else if (const auto* c = std::get_if<CommandResultRecord>(&r); c && c->kind == manip::command_t::SET_TARGETS) {
    while (!pending_targets_.empty() && pending_targets_.front().seq != c->seq) pending_targets_.pop_front();
    if (!pending_targets_.empty()) {
      if (c->accepted) {
        cue_.start_shoulder_m = pending_targets_.front().start_shoulder_m;
        cue_.goal_shoulder_m = pending_targets_.front().goal_shoulder_m;
        cue_seq_ = c->seq;
        changed = true;
      }
      pending_targets_.pop_front();
    }
  }
  if (changed) publish_targets();
}

void Bus::publish_targets() {
  publish(channels::kTargets, to_targets_message(cue_, cue_cycle_, cfg_.protocol.target_radius_m,
                                                 cfg_.session.perturbation.trigger_x2_shoulder_m, cue_seq_));
  next_targets_ns_ = monotonic_ns() + 1'000'000'000;
}

void Bus::publish_health() {
  manip::health_t h{};
  h.utime = wall_clock_us();
  if (links_.status) {
    const auto& s = *links_.status;
    h.cycle = s.cycle.load(std::memory_order_relaxed);
    h.mode = s.mode.load(std::memory_order_relaxed);
    h.fault_flags = static_cast<std::int32_t>(s.fault_flags.load(std::memory_order_relaxed));
    h.logger_drops = s.log_drops.load(std::memory_order_relaxed);
    h.publisher_drops = s.bus_drops.load(std::memory_order_relaxed);
    h.command_rejects = s.commands_rejected.load(std::memory_order_relaxed) + command_rejects();
  }
  if (links_.timing) {
    const TimingSnapshot t = links_.timing->snapshot();
    h.wakeup_latency_p50_us = t.latency_p50_us;
    h.wakeup_latency_p99_us = t.latency_p99_us;
    h.wakeup_latency_max_us = t.latency_max_us;
    h.compute_p99_us = t.compute_p99_us;
    h.compute_max_us = t.compute_max_us;
    h.overruns = t.overruns;
  }
  publish(channels::kHealth, h);
  if (links_.to_logger) links_.to_logger->push_growing(AuxRecord(h));
}

std::int64_t udp_socket_drops() {
  // Inodes of this process's sockets, then their drop counters in the
  // (network-namespace-local) UDP table.
  std::set<unsigned long> inodes;
  if (DIR* d = ::opendir("/proc/self/fd")) {
    while (const dirent* e = ::readdir(d)) {
      char link[300], target[128];
      std::snprintf(link, sizeof link, "/proc/self/fd/%s", e->d_name);
      const ssize_t n = ::readlink(link, target, sizeof target - 1);
      if (n <= 0) continue;
      target[n] = '\0';
      unsigned long ino = 0;
      if (std::sscanf(target, "socket:[%lu]", &ino) == 1) inodes.insert(ino);
    }
    ::closedir(d);
  }
  std::int64_t drops = 0;
  for (const char* table : {"/proc/self/net/udp", "/proc/self/net/udp6"}) {
    std::FILE* f = std::fopen(table, "r");
    if (!f) continue;
    char line[512];
    if (!std::fgets(line, sizeof line, f)) {  // header
      std::fclose(f);
      continue;
    }
    while (std::fgets(line, sizeof line, f)) {
      // sl local rem st tx:rx tr:when retrnsmt uid timeout inode ref pointer drops
      unsigned long ino = 0;
      long long dr = 0;
      char skip[8][64];
      if (std::sscanf(line, " %63s %63s %63s %63s %63s %63s %63s %63s %*s %lu %*s %*s %lld", skip[0], skip[1],
                      skip[2], skip[3], skip[4], skip[5], skip[6], skip[7], &ino, &dr) == 10 &&
          inodes.count(ino))
        drops += dr;
    }
    std::fclose(f);
  }
  return drops;
}

void Bus::poll(int timeout_ms) {
  if (lcm_) {
    // lcm handles one message per call: under a flood, take what is queued
    // (bounded, so live state and health still go out) instead of one per
    // poll, or LCM's subscription queue and the socket buffer overflow and
    // commands are lost unanswered.
    int handled = lcm_->handleTimeout(timeout_ms) > 0 ? 1 : 0;
    while (handled > 0 && handled < kMaxMessagesPerPoll && lcm_->handleTimeout(0) > 0) ++handled;
  }
  drain_loop();
  const std::int64_t now = monotonic_ns();
  if (now >= next_health_ns_) {
    publish_health();
    next_health_ns_ = now + static_cast<std::int64_t>(1e9 / cfg_.bus.health_rate_hz);
  }
  if (now >= next_targets_ns_) publish_targets();
}

void Bus::run(const std::atomic<bool>& stop) {
  while (!stop.load(std::memory_order_acquire)) poll(2);
  drain_loop();
  publish_health();
}

}  // namespace manip::runtime
