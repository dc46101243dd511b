#include "manip/canopen/drive_set.hpp"

namespace manip::canopen {

CanDriveSet::CanDriveSet(const CanConfig& cfg, std::vector<CanPort*> ports) : cfg_(cfg), ports_(std::move(ports)) {
  for (const auto& b : cfg_.buses) masters_.push_back(std::make_unique<Master>(cfg_, b.name));
  tx_.resize(masters_.size());
  tx_failed_.assign(masters_.size(), 0);
  for (std::size_t b = 0; b < masters_.size(); ++b) {
    for (std::size_t s = 0; s < masters_[b]->node_count(); ++s) {
      const DriveConfig& d = masters_[b]->drive(s);
      if (d.workspace_axis < 0 || d.workspace_axis > 1) continue;
      Axis& a = axes_[std::size_t(d.workspace_axis)];
      a.bus = b;
      a.slot = s;
      a.scale = AxisScaling::from(d);
      a.has_velocity = d.tpdo.contains(PdoObject::VelocityActual) || d.tpdo2.contains(PdoObject::VelocityActual);
      ++n_axes_;
    }
  }
}

void CanDriveSet::flush(std::size_t b, FrameBuffer& tx) {
  if (b < ports_.size() && ports_[b])
    for (const CanFrame& f : tx) {
      if (!ports_[b]->send(f)) tx_failed_[b] = 1;
      else if (recorder_) recorder_->record(now_us_, static_cast<uint8_t>(b), true, f);
    }
  tx.clear();
}

void CanDriveSet::propagate_fault(bool discard_pending) {
  // A fault (or start-up failure) on one bus stops the other bus in the same
  // cycle: its pending frames of this cycle are replaced by the safe ones.
  const bool now_faulted = faulted();
  const bool newly = now_faulted && !was_faulted_;
  was_faulted_ = now_faulted;
  // Only on the transition: while an acknowledged fault clears, the buses
  // leave Faulted one after the other and must not re-fault each other.
  if (!newly) return;
  const Error first = error();
  for (std::size_t b = 0; b < masters_.size(); ++b) {
    const Phase p = masters_[b]->phase();
    if (p == Phase::Cyclic || p == Phase::Resetting || p == Phase::Configuring || p == Phase::Starting) {
      if (discard_pending) tx_[b].clear();
      masters_[b]->fault(first, tx_[b]);
    }
  }
}

bool CanDriveSet::faulted() const {
  for (const auto& m : masters_)
    if (m->phase() == Phase::Faulted || m->phase() == Phase::Failed) return true;
  return false;
}

Error CanDriveSet::error() const {
  for (const auto& m : masters_)
    if ((m->phase() == Phase::Faulted || m->phase() == Phase::Failed) && m->error()) return m->error();
  return {};
}

const DriveSetFeedback& CanDriveSet::read(int64_t now) {
  now_us_ = now;
  for (std::size_t b = 0; b < masters_.size(); ++b) {
    tx_[b].clear();
    std::size_t n = 0;
    do {
      n = ports_[b]->receive(std::span<CanFrame>(rx_.data(), rx_.size()));
      if (recorder_)
        for (std::size_t i = 0; i < n; ++i) recorder_->record(now, static_cast<uint8_t>(b), false, rx_[i]);
      masters_[b]->handle(now, std::span<const CanFrame>(rx_.data(), n), tx_[b]);
    } while (n == rx_.size());
    if (tx_failed_[b]) {  // frames of the last cycle were refused: commands did not reach the drive
      tx_failed_[b] = 0;
      masters_[b]->fault(Error{ErrorCode::TxOverflow, 0, 0, 0, 0, 0, now}, tx_[b]);
    }
  }
  propagate_fault(false);
  for (std::size_t b = 0; b < masters_.size(); ++b) flush(b, tx_[b]);
  if (faulted()) enable_wanted_ = false;  // after a fault only an explicit enable() re-enables
  fb_.enabled = n_axes_ > 0;
  fb_.faulted = faulted();
  const double sync_s = masters_.empty() ? 0 : masters_[0]->sync_period_us() * 1e-6;
  for (int i = 0; i < n_axes_ && i < 2; ++i) {
    Axis& a = axes_[std::size_t(i)];
    const NodeStatus& ns = masters_[a.bus]->node(a.slot);
    fb_.position_m[i] = a.scale.position_m(ns.position_counts);
    if (a.has_velocity) {
      fb_.velocity_mps[i] = a.scale.velocity_mps(ns.velocity_units);
    } else if (ns.tpdo_received != a.prev_tpdos) {
      // One TPDO per SYNC: difference over the SYNC periods between samples.
      if (a.have_prev)
        fb_.velocity_mps[i] = a.scale.sign * double(ns.position_counts - a.prev_counts) / a.scale.counts_per_m /
                              (sync_s * double(ns.tpdo_received - a.prev_tpdos));
      a.prev_counts = ns.position_counts;
      a.prev_tpdos = ns.tpdo_received;
      a.have_prev = ns.has_feedback;
    }
    fb_.statusword[std::size_t(i)] = ns.statusword;
    fb_.digital_inputs[std::size_t(i)] = ns.digital_inputs;
    fb_.state[std::size_t(i)] = cia402::decode(ns.statusword);
    fb_.enabled &= fb_.state[std::size_t(i)] == cia402::State::OperationEnabled;
  }
  return fb_;
}

void CanDriveSet::write(const Vec2& force_n) {
  for (int i = 0; i < n_axes_ && i < 2; ++i) {
    Axis& a = axes_[std::size_t(i)];
    Master& m = *masters_[a.bus];
    const NodeStatus& ns = m.node(a.slot);
    if (m.phase() != Phase::Cyclic) continue;  // Faulted: the master forces the safe command
    const auto step = cia402::master_step(ns.statusword,
                                          enable_wanted_ ? cia402::Target::OperationEnabled : cia402::Target::Disabled,
                                          false, ns.controlword);
    const bool on = enable_wanted_ && cia402::decode(ns.statusword) == cia402::State::OperationEnabled;
    m.set_command(a.slot, step.controlword, on ? a.scale.torque_permille(force_n[i]) : int16_t{0});
  }
  for (std::size_t b = 0; b < masters_.size(); ++b) {
    tx_[b].clear();
    masters_[b]->update(now_us_, tx_[b]);
  }
  propagate_fault(true);
  for (std::size_t b = 0; b < masters_.size(); ++b) flush(b, tx_[b]);
  if (faulted()) enable_wanted_ = false;
}

Error CanDriveSet::run_until(const Ticker& tick, int64_t timeout_us, const std::function<bool()>& done,
                             ErrorCode on_timeout) {
  const int64_t start = tick();
  int64_t now = start;
  while (true) {
    read(now);
    write(Vec2::Zero());
    if (done()) return {};
    if (const Error e = error(); e && faulted()) return e;
    if (now - start > timeout_us) return Error{on_timeout, 0, 0, 0, 0, static_cast<uint32_t>(timeout_us / 1000), now};
    now = tick();
  }
}

Error CanDriveSet::configure(const Ticker& tick) {
  enable_wanted_ = false;
  const int64_t now = tick();
  for (auto& m : masters_) m->start(now);
  for (auto& a : axes_) a.have_prev = false;
  was_faulted_ = false;
  const int64_t timeout = int64_t(cfg_.master.boot_timeout_ms) * 1000 + 30'000'000;
  return run_until(tick, timeout, [&] {
    for (auto& m : masters_) if (m->phase() != Phase::Cyclic) return false;
    return true;
  }, ErrorCode::BootTimeout);
}

Error CanDriveSet::enable(const Ticker& tick) {
  if (faulted()) return error();
  enable_wanted_ = true;
  Error e = run_until(tick, int64_t(cfg_.master.enable_timeout_ms) * 1000, [&] { return fb_.enabled; },
                      ErrorCode::EnableTimeout);
  if (e) enable_wanted_ = false;
  return e;
}

Error CanDriveSet::disable(const Ticker& tick) {
  enable_wanted_ = false;
  return run_until(tick, int64_t(cfg_.master.enable_timeout_ms) * 1000, [&] {
    for (int i = 0; i < n_axes_; ++i)
      if (fb_.state[std::size_t(i)] == cia402::State::OperationEnabled) return false;
    return true;
  }, ErrorCode::EnableTimeout);
}

Error CanDriveSet::shutdown(const Ticker& tick) {
  enable_wanted_ = false;
  const Error before = error();
  const int64_t now = tick();
  for (auto& m : masters_) m->request_shutdown(now);
  int64_t t = now;
  const int64_t deadline = now + 10'000'000;
  while (t < deadline) {
    read(t);
    write(Vec2::Zero());
    bool all = true;
    for (auto& m : masters_) all &= m->phase() == Phase::Stopped;
    if (all) return before;
    t = tick();
  }
  return Error{ErrorCode::SdoTimeout, 0, 0, 0, 0, 0, t};
}

void CanDriveSet::stop(const Error& reason) {
  enable_wanted_ = false;
  if (faulted()) return;
  bool any = false;
  for (std::size_t b = 0; b < masters_.size(); ++b) {
    if (masters_[b]->phase() != Phase::Cyclic) continue;
    tx_[b].clear();
    masters_[b]->fault(Error{reason.code, reason.node, reason.index, reason.sub, reason.value, reason.detail, now_us_},
                       tx_[b]);
    any = true;
  }
  if (!any) return;
  was_faulted_ = true;  // every bus is in it already: nothing to propagate
  for (std::size_t b = 0; b < masters_.size(); ++b) flush(b, tx_[b]);
}

bool CanDriveSet::request_fault_reset() {
  bool ok = true;
  for (auto& m : masters_) {
    if (m->phase() == Phase::Faulted) ok &= m->request_fault_reset();
    else if (m->phase() == Phase::Failed) ok = false;  // start-up failure: only configure() again
  }
  return ok;
}

bool CanDriveSet::fault_acknowledgeable() const {
  bool any = false;
  for (const auto& m : masters_) {
    if (m->phase() == Phase::Failed) return false;
    if (m->phase() == Phase::Faulted) {
      if (!m->fault_acknowledgeable()) return false;
      any = true;
    }
  }
  return any;
}

uint32_t CanDriveSet::fault_resets_failed() const {
  uint32_t n = 0;
  for (const auto& m : masters_) n += m->fault_resets_failed();
  return n;
}

}  // namespace manip::canopen
