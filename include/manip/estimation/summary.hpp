#pragma once
// Results of the methods: one per (method, trial) for per-trial methods, and
// summaries per method for the session and for each perturbation angle.
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "manip/estimation/directional.hpp"
#include "manip/estimation/estimate.hpp"

namespace manip::estimation {

struct TrialResult {
  int trial{-1};
  double angle_deg{0};
  std::string method;
  ImpedanceEstimate est;
  // Validation against a simulator's twin (NaN for lab logs): NRMSE of Δx at T_est per axis.
  Vec2 nrmse_dx{Vec2::Constant(std::numeric_limits<double>::quiet_NaN())};
};

// Which trials a summary covers: the whole session, or one perturbation
// angle (degrees counter-clockwise from +x1, conventions.md).
struct SummaryGroup {
  enum class Kind { session, angle };
  Kind kind{Kind::session};
  double angle_deg{std::numeric_limits<double>::quiet_NaN()};  // NaN for the session

  static SummaryGroup session() { return {}; }
  static SummaryGroup angle(double deg) { return {Kind::angle, deg}; }
  [[nodiscard]] bool is_session() const { return kind == Kind::session; }
  [[nodiscard]] bool is_angle() const { return kind == Kind::angle; }
  // "session" or "angle 30" (rounded to whole degrees): the text of the JSON
  // "group" and the CSV "group" column, kept for compatibility.
  [[nodiscard]] std::string label() const;
  friend bool operator==(const SummaryGroup& a, const SummaryGroup& b) {
    return a.kind == b.kind && (a.kind == Kind::session || a.angle_deg == b.angle_deg);
  }
};

struct Summary {
  std::string method;
  SummaryGroup group;
  std::string kind;         // "mean (std) over trials" or "pooled fit (<se kind>)"
  bool pooled{false};
  int n_trials{0};
  Mat2 d_nspm{Mat2::Zero()}, k_npm{Mat2::Zero()};
  Mat2 d_spread{Mat2::Zero()}, k_spread{Mat2::Zero()};  // std over trials, or SE of the pooled fit
  Mat2 d_lo{Mat2::Zero()}, d_hi{Mat2::Zero()}, k_lo{Mat2::Zero()}, k_hi{Mat2::Zero()};  // 95% interval
  Mat2 m_kg{Mat2::Zero()};
  bool identifiable{true};
  std::string flag;
  int n_flagged_trials{0};
  std::optional<DisturbanceModel> disturbance;  // pem: the fitted model of the person's own motion
  // Per-angle summaries: the impedance along the push (directional.hpp), the
  // result to read for one angle; the 2x2 above is then flagged not identifiable.
  std::optional<DirectionalEstimate> directional;
};

// Mean (std) over per-trial estimates, laid out like Table 1, with the 95%
// interval of the mean (Student t) and the identifiability rule applied to
// the standard error of the mean.
Summary summarise_trials(const std::string& method, const SummaryGroup& group, const std::vector<const TrialResult*>& rs);
// A pooled fit as a summary: estimate (SE) and estimate ± ci_factor·SE.
Summary summarise_pooled(const std::string& method, const SummaryGroup& group, const ImpedanceEstimate& e);

}  // namespace manip::estimation
