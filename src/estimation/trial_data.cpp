#include "manip/estimation/trial_data.hpp"

#include <cmath>

#include "manip/common/errors.hpp"

namespace manip::estimation {
namespace {
Vec2 v2(const double a[2]) { return Vec2(a[0], a[1]); }
bool finite2(const double a[2]) { return std::isfinite(a[0]) && std::isfinite(a[1]); }
}  // namespace

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
  if (!(info_.sample_rate_hz > 0.0)) throw std::runtime_error("session message: sample_rate_hz must be positive");
  if (const auto why = info_.anthropometrics.invalid_reason())
    warnings_.push_back("session message: anthropometrics invalid (" + *why + "); M_BSP cannot be computed");
}

void TrialAssembler::drop(const std::string& reason) {
  if (!bad_) {
    bad_ = true;
    bad_reason_ = reason;
  }
}

void TrialAssembler::on_state(const manip::state_t& s) {
  ++states_;
  if (last_cycle_ >= 0 && s.cycle != last_cycle_ + 1) {
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
  const auto idx = s.cycle - cur_.start_cycle;
  if (idx != static_cast<std::int64_t>(cur_.x_m.size())) {
    drop("state cycle " + std::to_string(s.cycle) + " out of sequence");
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

void TrialAssembler::on_truth_state(const manip::state_t& s) {
  if (!in_trial_ || s.trial != cur_.trial || !has_session_) return;
  const auto idx = s.cycle - cur_.start_cycle;
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

void TrialAssembler::on_truth_impedance(const manip::impedance_truth_t& t) {
  if (!in_trial_ || t.trial != cur_.trial) return;
  cur_.has_truth = true;
  cur_.truth_m_kg << t.m_kg[0], t.m_kg[1], t.m_kg[2], t.m_kg[3];
  cur_.truth_d_nspm << t.d_nspm[0], t.d_nspm[1], t.d_nspm[2], t.d_nspm[3];
  cur_.truth_k_npm << t.k_npm[0], t.k_npm[1], t.k_npm[2], t.k_npm[3];
  cur_.truth_model = t.model;
}

void TrialAssembler::on_trial_event(const manip::trial_event_t& e) {
  if (!has_session_) {
    if (!warned_no_session_) {
      warned_no_session_ = true;
      throw std::runtime_error("no session message before the first trial event (not a manip session log?)");
    }
    return;
  }
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
      break;
    case manip::trial_event_t::ONSET:
      if (in_trial_ && e.trial == cur_.trial) {
        if (cur_.onset_index >= 0) drop("second ONSET event in the trial");
        cur_.onset_index = e.cycle - cur_.start_cycle;
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
  if (in_trial_) issues_.push_back({cur_.trial, "log ends inside the trial (no END event)"});
  in_trial_ = false;
}

}  // namespace manip::estimation
