#include "manip/estimation/trial_data.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "manip/common/errors.hpp"

namespace manip::estimation {
namespace {
Vec2 v2(const double a[2]) { return Vec2(a[0], a[1]); }
bool finite2(const double a[2]) { return std::isfinite(a[0]) && std::isfinite(a[1]); }
// a - b without overflow (cycles come from untrusted bytes; INT64_MIN/MAX
// must give a wrong-but-defined answer, never undefined behaviour).
std::int64_t sub_sat(std::int64_t a, std::int64_t b) {
  std::int64_t r = 0;
  if (__builtin_sub_overflow(a, b, &r)) return a > b ? INT64_MAX : INT64_MIN;
  return r;
}
}  // namespace

int reference_shift_for(const std::string& source) { return source.rfind("manip_sim", 0) == 0 ? 0 : 1; }

const char* to_string(PositionSource p) {
  switch (p) {
    case PositionSource::encoder: return "encoder";
    case PositionSource::reference: return "reference";
    case PositionSource::automatic: return "auto";
    case PositionSource::tracked: return "tracked";
  }
  return "auto";
}

std::optional<PositionSource> parse_position_source(std::string_view s) {
  for (const auto p : {PositionSource::encoder, PositionSource::reference, PositionSource::automatic, PositionSource::tracked})
    if (s == to_string(p)) return p;
  return std::nullopt;
}

PositionSource resolved_position(PositionSource requested, const std::string& source) {
  if (requested != PositionSource::automatic) return requested;
  return source.rfind("manip_rt", 0) == 0 ? PositionSource::reference : PositionSource::encoder;
}

std::vector<Vec2> aligned_reference(const TrialData& t, int shift) {
  const std::size_t n = t.x_m.size();
  const auto name = "trial " + std::to_string(t.trial) + ": ";
  if (t.x_ref_m.size() != n || n < 2) throw std::invalid_argument(name + "no admittance reference logged (x_ref) to use as the position");
  for (const auto& v : t.x_ref_m)
    if (!v.allFinite())
      throw std::invalid_argument(name + "the admittance reference (x_ref) is not finite: this log has none to use as the position");
  if (shift == 0) return t.x_ref_m;
  std::vector<Vec2> out(n);
  out[0] = 2.0 * t.x_ref_m[0] - t.x_ref_m[1];
  for (std::size_t k = 1; k < n; ++k) out[k] = t.x_ref_m[k - 1];
  return out;
}

SessionInfo session_info_from(const manip::session_t& m) {
  SessionInfo s = schema::from_message(m);
  if (const auto why = s.invalid_reason()) throw manip::InputError("session message: " + *why);
  return s;
}

void TrialAssembler::on_session(const manip::session_t& msg) {
  if (has_session_) {
    warnings_.push_back("second session message ignored (one log, one session)");
    return;
  }
  info_ = session_info_from(msg);
  rot_ = info_.frame.rotation();
  has_session_ = true;
}

void TrialAssembler::drop(const std::string& reason) {
  if (!bad_) {
    bad_ = true;
    bad_reason_ = reason;
  }
}

namespace {
// Release order within one cycle: a trial's START (and ONSET) come before the
// cycle's state, the truth of the cycle after it, END/ABORT last, so that the
// START cycle is the trial's first sample and the END cycle its last.
constexpr int kRankStart = 0, kRankOnset = 1, kRankState = 2, kRankTwin = 3, kRankTruth = 4, kRankEnd = 5;
}  // namespace

void TrialAssembler::hold(Pending&& p) {
  p.seq = seq_++;
  // Later than what was already released: nothing can be put before it any
  // more; process it now (the checks below then report it as out of order).
  if (released_any_ && (p.cycle < released_cycle_ || (p.cycle == released_cycle_ && p.rank < released_rank_))) {
    process(p);
    return;
  }
  // States arrive in cycle order, so this is nearly always a push_back.
  auto before = [](const Pending& a, const Pending& b) {
    return a.cycle != b.cycle ? a.cycle < b.cycle : a.rank < b.rank;
  };
  if (pending_.empty() || !before(p, pending_.back())) {
    pending_.push_back(std::move(p));
  } else {
    const auto it = std::upper_bound(pending_.begin(), pending_.end(), p, before);
    pending_.insert(it, std::move(p));
  }
}

void TrialAssembler::release_until(std::int64_t horizon_cycle) {
  const std::size_t cap = kMaxPendingFactor * static_cast<std::size_t>(tolerance_) + 64;
  while (!pending_.empty() &&
         (sub_sat(horizon_cycle, pending_.front().cycle) > tolerance_ || pending_.size() > cap)) {
    const Pending p = std::move(pending_.front());
    pending_.pop_front();
    released_any_ = true;
    released_cycle_ = p.cycle;
    released_rank_ = p.rank;
    process(p);
  }
}

void TrialAssembler::process(const Pending& p) {
  if (const auto* s = std::get_if<manip::state_t>(&p.msg)) {
    if (p.twin)
      do_truth_state(*s);
    else
      do_state(*s);
  } else if (const auto* e = std::get_if<manip::trial_event_t>(&p.msg)) {
    do_trial_event(*e);
  } else {
    do_truth_impedance(std::get<manip::impedance_truth_t>(p.msg));
  }
}

void TrialAssembler::on_state(const manip::state_t& s) {
  ++states_;
  latest_cycle_ = s.cycle;
  hold(Pending{s.cycle, kRankState, 0, false, s});
  // Only states move the window: their counter is what the log guarantees
  // (gapless, increasing); an event's cycle may be anything.
  release_until(s.cycle);
}

void TrialAssembler::on_truth_state(const manip::state_t& s) {
  latest_cycle_ = std::max(latest_cycle_, s.cycle);
  hold(Pending{s.cycle, kRankTwin, 0, true, s});
}

void TrialAssembler::on_truth_impedance(const manip::impedance_truth_t& t) {
  // No cycle of its own: it belongs with the messages that arrived before it.
  hold(Pending{latest_cycle_, kRankTruth, 0, false, t});
}

void TrialAssembler::on_trial_event(const manip::trial_event_t& e) {
  // Checked on arrival, so that the error points at this event.
  if (!has_session_) throw std::runtime_error("no session message before the first trial event (not a manip session log?)");
  int rank = kRankOnset;
  if (e.kind == manip::trial_event_t::START) rank = kRankStart;
  if (e.kind == manip::trial_event_t::END || e.kind == manip::trial_event_t::ABORT) rank = kRankEnd;
  hold(Pending{e.cycle, rank, 0, false, e});
}

void TrialAssembler::do_state(const manip::state_t& s) {
  if (last_cycle_ >= 0 && sub_sat(s.cycle, last_cycle_) != 1) {
    ++gaps_;
    if (in_trial_)
      drop("gap in the cycle counter (" + std::to_string(last_cycle_) + " -> " + std::to_string(s.cycle) + ")");
  }
  last_cycle_ = s.cycle;
  if (!in_trial_ || s.trial != cur_.trial) return;
  if (!has_session_) return;
  if (!finite2(s.x_workspace_m) || !finite2(s.f_sensor_workspace_n) || !finite2(s.u_pert_workspace_n)) {
    drop("non-finite sample at cycle " + std::to_string(s.cycle));
    return;
  }
  const auto idx = sub_sat(s.cycle, cur_.start_cycle);
  if (idx != static_cast<std::int64_t>(cur_.x_m.size())) {
    drop("state cycle " + std::to_string(s.cycle) + " out of sequence (expected cycle " +
         std::to_string(cur_.start_cycle + static_cast<std::int64_t>(cur_.x_m.size())) + ")");
    return;
  }
  // Same arithmetic as WorkspaceToShoulder::point_to_shoulder / vector_to_shoulder.
  const Vec2& o = info_.frame.origin_in_shoulder_m;
  cur_.x_m.push_back(rot_ * v2(s.x_workspace_m) + o);
  if (!keep_all_) return;
  cur_.f_sensor_n.push_back(rot_ * v2(s.f_sensor_workspace_n));
  cur_.u_pert_n.push_back(rot_ * v2(s.u_pert_workspace_n));
  cur_.x_ref_m.push_back(rot_ * v2(s.x_ref_workspace_m) + o);
  cur_.xd_ref_m.push_back(rot_ * v2(s.xd_ref_workspace_mps));
  cur_.xdd_ref_m.push_back(rot_ * v2(s.xdd_ref_workspace_mps2));
}

void TrialAssembler::do_truth_state(const manip::state_t& s) {
  if (!in_trial_ || s.trial != cur_.trial || !has_session_) return;
  const auto idx = sub_sat(s.cycle, cur_.start_cycle);
  if (idx != static_cast<std::int64_t>(cur_.x_twin_m.size())) return;  // misaligned twin: ignore it
  if (cur_.x_twin_m.empty()) {
    cur_.x_twin_m.reserve(cur_.x_m.capacity());
    cur_.xd_twin_m.reserve(cur_.x_m.capacity());
    cur_.xdd_twin_m.reserve(cur_.x_m.capacity());
  }
  cur_.x_twin_m.push_back(rot_ * v2(s.x_ref_workspace_m) + info_.frame.origin_in_shoulder_m);
  cur_.xd_twin_m.push_back(rot_ * v2(s.xd_ref_workspace_mps));
  cur_.xdd_twin_m.push_back(rot_ * v2(s.xdd_ref_workspace_mps2));
}

void TrialAssembler::do_truth_impedance(const manip::impedance_truth_t& t) {
  // trial -1: a truth of the whole session, not of a trial (written inside
  // the last perturbed trial, before its END: never attached to that trial).
  if (t.trial == -1) {
    auto finite4 = [](const double a[4]) {
      return std::isfinite(a[0]) && std::isfinite(a[1]) && std::isfinite(a[2]) && std::isfinite(a[3]);
    };
    if (t.model != kApparentTruthModel) {
      warnings_.push_back("session-level truth (MANIP_TRUTH_IMPEDANCE, trial -1) of unknown model '" + t.model +
                          "' ignored");
    } else if (!finite4(t.m_kg) || !finite4(t.d_nspm) || !finite4(t.k_npm) || !std::isfinite(t.t_est_s)) {
      warnings_.push_back("apparent truth (MANIP_TRUTH_IMPEDANCE, trial -1) with non-finite values ignored");
    } else if (apparent_) {
      warnings_.push_back("second apparent truth (MANIP_TRUTH_IMPEDANCE, trial -1) ignored");
    } else {
      ApparentTruth a;
      a.m_kg << t.m_kg[0], t.m_kg[1], t.m_kg[2], t.m_kg[3];
      a.d_nspm << t.d_nspm[0], t.d_nspm[1], t.d_nspm[2], t.d_nspm[3];
      a.k_npm << t.k_npm[0], t.k_npm[1], t.k_npm[2], t.k_npm[3];
      a.t_est_s = t.t_est_s;
      a.model = t.model;
      apparent_ = a;
    }
    return;
  }
  if (!in_trial_ || t.trial != cur_.trial) return;
  cur_.has_truth = true;
  cur_.truth_m_kg << t.m_kg[0], t.m_kg[1], t.m_kg[2], t.m_kg[3];
  cur_.truth_d_nspm << t.d_nspm[0], t.d_nspm[1], t.d_nspm[2], t.d_nspm[3];
  cur_.truth_k_npm << t.k_npm[0], t.k_npm[1], t.k_npm[2], t.k_npm[3];
  cur_.truth_model = t.model;
}

void TrialAssembler::do_trial_event(const manip::trial_event_t& e) {
  switch (e.kind) {
    case manip::trial_event_t::START:
      if (in_trial_) issues_.push_back({cur_.trial, "no END/ABORT before trial " + std::to_string(e.trial) + " started"});
      cur_ = TrialData{};
      cur_.trial = e.trial;
      cur_.start_cycle = e.cycle;
      cur_.perturbed = e.perturbed;
      cur_.angle_rad = e.pert_angle_rad;
      cur_.amplitude_n = e.pert_amplitude_n;
      keep_all_ = keep_unperturbed_signals_ || cur_.perturbed;
      {
        // Trials of a session have similar lengths: reserving the previous
        // one's plus 1/8 avoids most of the reallocation copies of push_back.
        const std::size_t guess = last_size_ + last_size_ / 8;
        cur_.x_m.reserve(guess);
        if (keep_all_) {
          for (auto* v : {&cur_.f_sensor_n, &cur_.u_pert_n, &cur_.x_ref_m, &cur_.xd_ref_m, &cur_.xdd_ref_m})
            v->reserve(guess);
        }
      }
      in_trial_ = true;
      bad_ = false;
      bad_reason_.clear();
      // The state of the START cycle was already released: this START came
      // later than the reorder window allows, and its first samples are gone.
      if (last_cycle_ >= e.cycle)
        drop("START event (cycle " + std::to_string(e.cycle) + ") arrived after the state of cycle " +
             std::to_string(last_cycle_) + ", more than the reorder tolerance of " + std::to_string(tolerance_) +
             " cycles late");
      break;
    case manip::trial_event_t::ONSET:
      if (in_trial_ && e.trial == cur_.trial) {
        if (cur_.onset_index >= 0) drop("second ONSET event in the trial");
        cur_.onset_index = sub_sat(e.cycle, cur_.start_cycle);
        cur_.angle_rad = e.pert_angle_rad;
        cur_.amplitude_n = e.pert_amplitude_n;
      }
      break;
    case manip::trial_event_t::END:
    case manip::trial_event_t::ABORT: {
      if (!in_trial_ || e.trial != cur_.trial) {
        warnings_.push_back("END/ABORT of trial " + std::to_string(e.trial) + " without its START; ignored");
        break;
      }
      in_trial_ = false;
      // The trial ends at the END cycle: drop samples a writer labelled with
      // the trial after it (only possible when the END came late).
      const auto end_index = sub_sat(e.cycle, cur_.start_cycle);  // index of the END cycle
      if (end_index >= 0 && end_index < INT64_MAX && static_cast<std::int64_t>(cur_.x_m.size()) > end_index + 1) {
        const auto n = static_cast<std::size_t>(end_index + 1);
        for (auto* v : {&cur_.x_m, &cur_.f_sensor_n, &cur_.u_pert_n, &cur_.x_ref_m, &cur_.xd_ref_m, &cur_.xdd_ref_m,
                        &cur_.x_twin_m, &cur_.xd_twin_m, &cur_.xdd_twin_m})
          if (v->size() > n) v->resize(n);
      }
      if (!cur_.x_m.empty()) last_size_ = cur_.x_m.size();
      if (e.kind == manip::trial_event_t::ABORT) {
        issues_.push_back({cur_.trial, "aborted (" + e.reason + ")"});
        break;
      }
      cur_.ended = true;
      if (bad_) {
        issues_.push_back({cur_.trial, bad_reason_});
        break;
      }
      if (cur_.perturbed && (cur_.onset_index < 0 || cur_.onset_index >= static_cast<std::int64_t>(cur_.size()))) {
        issues_.push_back({cur_.trial, "perturbed trial without a perturbation onset inside it"});
        // Still hand it over: it is a usable unperturbed movement for the PSD.
        cur_.perturbed = false;
        cur_.onset_index = -1;
      }
      if (cur_.x_twin_m.size() != cur_.x_m.size()) {
        cur_.x_twin_m.clear();
        cur_.xd_twin_m.clear();
        cur_.xdd_twin_m.clear();
      }
      cb_(info_, std::move(cur_));
      cur_ = TrialData{};
      break;
    }
    default:
      warnings_.push_back("unknown trial event kind " + std::to_string(e.kind) + " at cycle " + std::to_string(e.cycle));
  }
}

void TrialAssembler::finish() {
  while (!pending_.empty()) {
    const Pending p = std::move(pending_.front());
    pending_.pop_front();
    released_any_ = true;
    released_cycle_ = p.cycle;
    released_rank_ = p.rank;
    process(p);
  }
  if (in_trial_) issues_.push_back({cur_.trial, "log ends inside the trial (no END event)"});
  in_trial_ = false;
}

}  // namespace manip::estimation
