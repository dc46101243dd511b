#include "manip/control/protocol.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "manip/trial_event_t.hpp"

namespace manip::control {

std::vector<TrialSpec> make_schedule(const ProtocolConfig& protocol, const PerturbationConfig& perturbation,
                                     int perturbed_count) {
  return make_schedule(protocol.movements, perturbation.angles_deg, perturbation.repeats_per_angle, perturbed_count,
                       protocol.seed);
}

std::vector<TrialSpec> make_schedule(int movements, const std::vector<double>& angles_deg, int repeats_per_angle,
                                     int perturbed_count, std::uint64_t seed) {
  PortableRng rng(seed);
  // The full perturbation multiset (each angle `repeats` times), shuffled.
  std::vector<double> angles;
  for (int r = 0; r < repeats_per_angle; ++r)
    for (double a : angles_deg) angles.push_back(a);
  portable_shuffle(angles.begin(), angles.end(), rng);
  const auto k = static_cast<std::size_t>(std::clamp(perturbed_count, 0, static_cast<int>(angles.size())));
  angles.resize(k);
  // Slots: the first k of a shuffled slot list are perturbed, assigned the
  // shuffled angles in slot order.
  std::vector<int> slots(static_cast<std::size_t>(movements));
  for (std::size_t i = 0; i < slots.size(); ++i) slots[i] = static_cast<int>(i);
  portable_shuffle(slots.begin(), slots.end(), rng);
  std::vector<int> chosen(slots.begin(), slots.begin() + static_cast<long>(std::min(k, slots.size())));
  std::sort(chosen.begin(), chosen.end());
  std::vector<TrialSpec> out(static_cast<std::size_t>(movements));
  for (std::size_t i = 0; i < chosen.size(); ++i) {
    auto& t = out[static_cast<std::size_t>(chosen[i])];
    t.perturbed = true;
    t.angle_rad = angles[i] * std::numbers::pi / 180.0;
  }
  return out;
}

Protocol::Protocol(const ControlConfig& cfg)
    : p_(cfg.protocol),
      profile_{cfg.session.perturbation.duration_s, cfg.session.perturbation.amplitude_n},
      fs_(cfg.session.sample_rate_hz),
      start_(cfg.protocol.start_shoulder_m),
      goal_(cfg.protocol.goal_shoulder_m),
      start_hold_cycles_(std::max<std::int64_t>(1, std::llround(cfg.protocol.start_hold_s * fs_))),
      goal_hold_cycles_(std::max<std::int64_t>(1, std::llround(cfg.protocol.goal_hold_s * fs_))),
      timeout_cycles_(std::llround(cfg.protocol.trial_timeout_s * fs_)),
      schedule_(make_schedule(cfg.protocol, cfg.perturbation, cfg.perturbed_count())),
      requeue_rng_(cfg.protocol.seed ^ 0x5EED0F00DULL),
      trigger_(cfg.session.perturbation.trigger_x2_shoulder_m, fs_) {
  // Room for every possible re-queue, so insert() never reallocates in the loop.
  schedule_.reserve(schedule_.size() + static_cast<std::size_t>(cfg.perturbed_count()) *
                                           static_cast<std::size_t>(cfg.protocol.max_requeues) +
                    1);
}

bool Protocol::in_start(const Vec2& x_sh, const Vec2& xd_sh) const {
  return (x_sh - start_).norm() <= p_.target_radius_m && xd_sh.norm() <= p_.rest_speed_mps;
}
bool Protocol::in_goal(const Vec2& x_sh, const Vec2& xd_sh) const {
  return (x_sh - goal_).norm() <= p_.target_radius_m && xd_sh.norm() <= p_.rest_speed_mps;
}

void Protocol::begin() {
  if (phase_ == Phase::kDone) return;
  phase_ = Phase::kReturn;
  hold_cycles_ = 0;
}

TrialEventRecord Protocol::make_event(std::int8_t kind, std::int64_t cycle, std::int64_t utime) const {
  TrialEventRecord e;
  e.utime = utime;
  e.cycle = cycle;
  e.trial = trial_;
  e.kind = kind;
  e.perturbed = current_.perturbed;
  e.start_shoulder_m = start_;
  e.goal_shoulder_m = goal_;
  e.pert_angle_rad = current_.perturbed ? current_.angle_rad : 0.0;
  e.pert_amplitude_n = current_.perturbed ? profile_.amplitude_n : 0.0;
  e.pert_duration_s = current_.perturbed ? profile_.duration_s : 0.0;
  return e;
}

bool Protocol::select_next() {
  if (next_ >= static_cast<int>(schedule_.size())) return false;
  if (pert_enabled_ || !schedule_[static_cast<std::size_t>(next_)].perturbed) return true;
  for (std::size_t j = static_cast<std::size_t>(next_) + 1; j < schedule_.size(); ++j) {
    if (!schedule_[j].perturbed) {
      // Move slot j to next_, keeping the order of the deferred perturbed slots.
      std::rotate(schedule_.begin() + next_, schedule_.begin() + static_cast<long>(j),
                  schedule_.begin() + static_cast<long>(j) + 1);
      return true;
    }
  }
  return false;
}

void Protocol::start_trial(std::int64_t cycle, std::int64_t utime, ProtocolEvents& out) {
  current_ = schedule_[static_cast<std::size_t>(next_++)];
  trial_ = next_trial_index_++;
  trial_active_ = true;
  trial_start_cycle_ = cycle;
  hold_cycles_ = 0;
  if (current_.perturbed)
    trigger_.arm(current_.angle_rad, profile_, goal_.y() >= start_.y() ? 1.0 : -1.0);
  else
    trigger_.clear();
  phase_ = Phase::kReach;
  ++n_.started;
  out.push(make_event(manip::trial_event_t::START, cycle, utime));
}

void Protocol::end_trial_abort(std::int64_t cycle, std::int64_t utime, AbortReason why, ProtocolEvents& out) {
  TrialEventRecord e = make_event(manip::trial_event_t::ABORT, cycle, utime);
  e.reason = why;
  ++n_.aborted;
  if (current_.perturbed) {
    if (current_.requeues < p_.max_requeues) {
      TrialSpec again = current_;
      ++again.requeues;
      const auto size = static_cast<std::uint64_t>(schedule_.size());
      const auto next = static_cast<std::uint64_t>(next_);
      // Insert before index in [next+1, size] (later than the next slot when there is one).
      std::uint64_t pos = size;
      if (size > next) pos = next + 1 + requeue_rng_.below(size - next);
      if (schedule_.size() < schedule_.capacity()) {
        schedule_.insert(schedule_.begin() + static_cast<long>(pos), again);
        ++n_.requeued;
      } else {
        e.dropped = true;
        ++n_.dropped;
      }
    } else {
      e.dropped = true;
      ++n_.dropped;
    }
  }
  out.push(e);
  trigger_.clear();
  trial_active_ = false;
  hold_cycles_ = 0;
  u_pert_sh_.setZero();
}

void Protocol::update(std::int64_t cycle, std::int64_t utime, const Vec2& x_sh, const Vec2& xd_sh,
                      ProtocolEvents& out) {
  const bool onset = trigger_.update(cycle, x_sh.y(), xd_sh.y());
  u_pert_sh_.setZero();
  switch (phase_) {
    case Phase::kNone:
    case Phase::kDone:
      return;
    case Phase::kReturn:
    case Phase::kWaiting: {
      if (!select_next()) {
        phase_ = remaining() == 0 ? Phase::kDone : Phase::kWaiting;
        hold_cycles_ = 0;
        return;
      }
      phase_ = Phase::kReturn;
      hold_cycles_ = in_start(x_sh, xd_sh) ? hold_cycles_ + 1 : 0;
      if (hold_cycles_ >= start_hold_cycles_) start_trial(cycle, utime, out);
      return;
    }
    case Phase::kReach:
    case Phase::kPerturbation:
    case Phase::kGoalHold: {
      if (onset) {
        ++n_.onsets;
        out.push(make_event(manip::trial_event_t::ONSET, cycle, utime));
      }
      const bool pert_active = trigger_.active(cycle);
      u_pert_sh_ = trigger_.force_shoulder_n(cycle);
      hold_cycles_ = (!pert_active && in_goal(x_sh, xd_sh)) ? hold_cycles_ + 1 : 0;
      phase_ = pert_active ? Phase::kPerturbation : (hold_cycles_ > 0 ? Phase::kGoalHold : Phase::kReach);
      if (hold_cycles_ >= goal_hold_cycles_) {
        out.push(make_event(manip::trial_event_t::END, cycle, utime));
        ++n_.completed;
        if (current_.perturbed) ++n_.perturbed_completed;
        trigger_.clear();
        trial_active_ = false;
        hold_cycles_ = 0;
        phase_ = Phase::kReturn;
      } else if (cycle - trial_start_cycle_ >= timeout_cycles_) {
        end_trial_abort(cycle, utime, AbortReason::kTimeout, out);
        phase_ = Phase::kReturn;
      }
      return;
    }
  }
}

void Protocol::abort_trial(std::int64_t cycle, std::int64_t utime, AbortReason why, ProtocolEvents& out) {
  if (trial_active_) end_trial_abort(cycle, utime, why, out);
  if (phase_ != Phase::kDone && phase_ != Phase::kNone) phase_ = Phase::kReturn;
}

void Protocol::suspend(std::int64_t cycle, std::int64_t utime, AbortReason why, ProtocolEvents& out) {
  if (trial_active_) end_trial_abort(cycle, utime, why, out);
  if (phase_ != Phase::kDone) phase_ = Phase::kNone;
  hold_cycles_ = 0;
}

void Protocol::finish(std::int64_t cycle, std::int64_t utime, AbortReason why, ProtocolEvents& out) {
  if (trial_active_) end_trial_abort(cycle, utime, why, out);
  phase_ = Phase::kDone;
}

Reject Protocol::start_now(std::int64_t cycle, std::int64_t utime, const Vec2& x_sh, ProtocolEvents& out) {
  if (trial_active_) return Reject::kTrialActive;
  if (phase_ != Phase::kReturn && phase_ != Phase::kWaiting) return Reject::kNotAllowedInMode;
  if ((x_sh - start_).norm() > p_.target_radius_m) return Reject::kHandNotInStart;
  if (!select_next()) return Reject::kSessionDone;
  start_trial(cycle, utime, out);
  return Reject::kNone;
}

void Protocol::set_targets(const Vec2& start_sh, const Vec2& goal_sh) {
  start_ = start_sh;
  goal_ = goal_sh;
  hold_cycles_ = 0;
}

void Protocol::set_perturbations_enabled(bool on, std::int64_t cycle, std::int64_t utime, ProtocolEvents& out) {
  if (!on && trial_active_ && current_.perturbed && !trigger_.fired()) {
    end_trial_abort(cycle, utime, AbortReason::kPerturbationsOff, out);
    phase_ = Phase::kReturn;
  }
  pert_enabled_ = on;
}

}  // namespace manip::control
