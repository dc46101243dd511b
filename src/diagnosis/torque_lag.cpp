#include "manip/diagnosis/torque_lag.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "manip/common/errors.hpp"
#include "manip/common/rng.hpp"
#include "manip/diagnosis/report.hpp"

namespace manip::diagnosis {
// Named, not anonymous: the unity build puts this file next to engine.cpp's helpers.
namespace lagfit {

using Eigen::MatrixXd;
using Eigen::VectorXd;

// 0-60 ms: amplifier and anti-aliasing filters sit at 0.3-16 ms; a skew of
// the acquisition channels can be anything; 60 ms (a 2.7 Hz low pass) covers
// the detection study's largest magnitude (docs/diagnosis.md).
constexpr double kLagMax_s = 0.060;
constexpr double kLagStep_s = 0.0005;

// y' = (u - y) / T with u linear between samples (first-order hold; exact):
// y_{k+1} = a y_k + (1 - a) u_k + c (u_{k+1} - u_k), a = e^{-dt/T},
// c = 1 - (T/dt)(1 - a). The same discretisation as the generator's
// (synthetic.cpp), written once more here on whole columns.
void lag_column(const std::vector<double>& u, double lag_s, double dt_s, std::vector<double>& y) {
  y = u;
  if (lag_s <= 0.0 || u.empty()) return;
  const double a = std::exp(-dt_s / lag_s);
  const double c = 1.0 - lag_s / dt_s * (1.0 - a);
  for (std::size_t k = 1; k < u.size(); ++k) y[k] = a * y[k - 1] + (1.0 - a) * u[k - 1] + c * (u[k] - u[k - 1]);
}

struct BlockStats {
  MatrixXd G;
  VectorXd h;
  double yy = 0.0;
  void add(const BlockStats& o) {
    G += o.G;
    h += o.h;
    yy += o.yy;
  }
};

double sse_at(const BlockStats& s, const VectorXd& th) { return s.yy - 2.0 * th.dot(s.h) + th.dot(s.G * th); }
VectorXd solve(const BlockStats& s) { return s.G.completeOrthogonalDecomposition().solve(s.h); }

}  // namespace lagfit

TorqueLagFit fit_torque_lag(const Dataset& d, const Diagnosis& res, const std::vector<std::unique_ptr<Mechanism>>& lib,
                            const EngineOptions& opt) {
  using namespace lagfit;
  using Eigen::MatrixXd;
  using Eigen::VectorXd;
  TorqueLagFit f;
  if (d.is_planar() || d.segments.size() != 1) {
    f.why_not = "single-joint records only";
    return f;
  }
  const auto& g = d.segments.front();
  // The model's columns: the baseline's, then the named mechanisms' at their reported shapes.
  std::vector<std::vector<double>> cols = g.base;
  std::vector<std::string> names = d.base_names, units = d.base_units;
  std::size_t history = 0;
  for (const auto& m : lib)
    if (m->not_applicable(d).empty()) history = std::max(history, m->history_samples(d));
  for (std::size_t a = 0; a < res.accepted.size(); ++a)
    for (const auto& m : lib)
      if (m->id() == res.accepted[a]) {
        const auto c = m->columns(d, res.shape_of(a));
        for (const auto& col : c.front()) cols.push_back(col);
        for (const auto& gi : m->gains()) {
          names.push_back(gi.name);
          units.push_back(gi.unit);
        }
      }
  const auto p = static_cast<Eigen::Index>(cols.size());
  // The engine's cross-validation design, so the lag's folds are the search's.
  if (opt.folds < 3) {
    f.why_not = "the lag's cross-validation needs at least 3 folds";
    return f;
  }
  const int K = opt.folds;
  std::vector<CvBlock> spans;
  try {
    spans = cv_blocks(d, opt, history);
  } catch (const InputError&) {
    f.why_not = "record too short for the lag's cross-validation";
    return f;
  }
  // With a configured inertia the target is tau_m - I a; the lag acts on
  // I a too: target(T) = y + I a - I LP_T[a].
  const bool fixed_i = d.inertia_fixed;
  auto stats_at = [&](double lag_s) {
    std::vector<std::vector<double>> lc(cols.size());
    for (std::size_t c = 0; c < cols.size(); ++c) lag_column(cols[c], lag_s, d.dt_s, lc[c]);
    std::vector<double> y = g.y;
    if (fixed_i) {
      std::vector<double> la;
      lag_column(g.acc, lag_s, d.dt_s, la);
      for (std::size_t i = 0; i < y.size(); ++i) y[i] += d.fixed_inertia * (g.acc[i] - la[i]);
    }
    std::vector<BlockStats> bs(spans.size(), BlockStats{MatrixXd::Zero(p, p), VectorXd::Zero(p), 0.0});
    VectorXd x(p);
    for (std::size_t b = 0; b < spans.size(); ++b)
      for (std::size_t i = spans[b].begin; i < spans[b].end; ++i) {
        for (Eigen::Index c = 0; c < p; ++c) x(c) = lc[static_cast<std::size_t>(c)][i];
        bs[b].G.selfadjointView<Eigen::Lower>().rankUpdate(x);
        bs[b].h += x * y[i];
        bs[b].yy += y[i] * y[i];
      }
    for (auto& s : bs) s.G = s.G.selfadjointView<Eigen::Lower>();
    return bs;
  };
  for (double t = 0.0; t <= kLagMax_s + 1e-12; t += kLagStep_s) f.grid_s.push_back(t);
  const std::size_t ng = f.grid_s.size();
  std::vector<std::vector<BlockStats>> per(ng);
  for (std::size_t k = 0; k < ng; ++k) per[k] = stats_at(f.grid_s[k]);
  auto total = [&](std::size_t k, const std::vector<std::size_t>& which) {
    BlockStats s{MatrixXd::Zero(p, p), VectorXd::Zero(p), 0.0};
    for (const auto b : which) s.add(per[k][b]);
    return s;
  };
  std::vector<std::size_t> all(spans.size());
  for (std::size_t b = 0; b < all.size(); ++b) all[b] = b;
  // Held-out: each fold's lag chosen on the others.
  for (int k = 0; k < K; ++k) {
    std::vector<std::size_t> tr, te;
    for (std::size_t b = 0; b < spans.size(); ++b) (spans[b].fold == k ? te : tr).push_back(b);
    std::size_t best = 0;
    double best_sse = 0.0;
    for (std::size_t j = 0; j < ng; ++j) {
      const auto s = total(j, tr);
      const double v = sse_at(s, solve(s));
      if (j == 0 || v < best_sse) {
        best_sse = v;
        best = j;
      }
    }
    const double e0 = sse_at(total(0, te), solve(total(0, tr)));
    const double e1 = sse_at(total(best, te), solve(total(best, tr)));
    f.fold_gain.push_back((e0 - e1) / e0);
  }
  f.test = stats::one_sided_t(f.fold_gain);
  // Full data: the grid's best, refined by the parabola through its neighbours.
  auto best_lag = [&](const std::vector<std::size_t>& which, bool* edge) {
    std::vector<double> sse(ng);
    for (std::size_t j = 0; j < ng; ++j) {
      const auto s = total(j, which);
      sse[j] = sse_at(s, solve(s));
    }
    const auto jb = static_cast<std::size_t>(std::min_element(sse.begin(), sse.end()) - sse.begin());
    if (edge) *edge = jb + 1 == ng;
    double t = f.grid_s[jb];
    if (jb > 0 && jb + 1 < ng) {
      const double v = stats::parabola_vertex(f.grid_s[jb - 1], sse[jb - 1], f.grid_s[jb], sse[jb], f.grid_s[jb + 1], sse[jb + 1]);
      if (std::isfinite(v) && std::fabs(v - t) <= kLagStep_s) t = v;
    }
    return std::pair{t, sse};
  };
  const auto [lag_all, sse_all] = best_lag(all, &f.at_edge);
  f.sse = sse_all;
  // One more candidate beside the library's round 1: Bonferroni over them
  // all keeps the family-wise level of a clean record's diagnosis.
  std::size_t family = 1;
  if (!res.rounds.empty())
    for (const auto& c : res.rounds.front().candidates) family += c.not_applicable.empty() ? 1 : 0;
  f.alpha = opt.alpha / static_cast<double>(family);
  f.significant = f.test.p_value < f.alpha && f.test.mean > 0.0 && !f.at_edge;
  auto params_at = [&](double lag_s, const std::vector<std::size_t>& which) {
    const auto bs = stats_at(lag_s);
    BlockStats s{MatrixXd::Zero(p, p), VectorXd::Zero(p), 0.0};
    for (const auto b : which) s.add(bs[b]);
    return solve(s);
  };
  const VectorXd th = params_at(lag_all, all);
  const VectorXd th0 = solve(total(0, all));  // T = 0 is the grid's first point
  // Block bootstrap: the lag (grid and parabola) and the gains at it.
  std::vector<double> lags;
  std::vector<std::vector<double>> gains(static_cast<std::size_t>(p));
  PortableRng rng(opt.seed ^ 0x7a6c61675f74ull);
  std::vector<std::size_t> pick(spans.size());
  for (int r = 0; r < opt.bootstrap; ++r) {
    for (auto& b : pick) b = static_cast<std::size_t>(rng.below(spans.size()));
    const double t = best_lag(pick, nullptr).first;
    lags.push_back(t);
    // The gains at the replicate's lag, interpolated between the grid's
    // neighbours (the columns are smooth in T; a filter pass per replicate
    // would cost a grid point each).
    const auto j = std::min<std::size_t>(static_cast<std::size_t>(t / kLagStep_s), ng - 2);
    const double w = std::clamp((t - f.grid_s[j]) / kLagStep_s, 0.0, 1.0);
    const VectorXd a = solve(total(j, pick)), b = solve(total(j + 1, pick));
    for (Eigen::Index c = 0; c < p; ++c) gains[static_cast<std::size_t>(c)].push_back((1.0 - w) * a(c) + w * b(c));
  }
  auto interval = [&](double v, const std::vector<double>& s) {
    return s.empty() ? Interval{v, v, v} : Interval{v, stats::percentile(s, 2.5), stats::percentile(s, 97.5)};
  };
  f.lag_s = interval(lag_all, lags);
  for (Eigen::Index c = 0; c < p; ++c) {
    const auto cu = static_cast<std::size_t>(c);
    f.params.push_back({names[cu], units[cu], interval(th(c), gains[cu])});
    f.params_no_lag.push_back({names[cu], units[cu], {th0(c), th0(c), th0(c)}});
  }
  f.done = true;
  return f;
}

std::string torque_lag_text(const TorqueLagFit& f) {
  std::string o = "\nTorque-channel lag (every column through 1/(1 + T s), T 0-60 ms; output error, each fold's T chosen on the others):\n";
  if (!f.done) return o + "  not fitted: " + f.why_not + "\n";
  char buf[256];
  std::snprintf(buf, sizeof buf, "  held-out gain %+.4f +- %.4f over %d folds, p %.2g (level %.3g: Bonferroni with round 1): %s\n", f.test.mean,
                f.test.se, f.test.n, f.test.p_value, f.alpha,
                f.significant ? "SIGNIFICANT" : (f.at_edge ? "the optimum on the 60 ms edge (not a channel lag)" : "no significant lag"));
  o += buf;
  std::snprintf(buf, sizeof buf, "  T = %s [%s, %s] ms\n", g4(f.lag_s.value * 1e3).c_str(), g4(f.lag_s.lo * 1e3).c_str(),
                g4(f.lag_s.hi * 1e3).c_str());
  o += buf;
  if (f.significant) {
    o += "  the model at T (block bootstrap), against T = 0:\n";
    for (std::size_t i = 0; i < f.params.size(); ++i) {
      const auto& q = f.params[i];
      o += "    " + q.name + " = " + g4(q.est.value) + " [" + g4(q.est.lo) + ", " + g4(q.est.hi) + "] " + q.unit + " (T = 0: " +
           g4(f.params_no_lag[i].est.value) + ")\n";
    }
  }
  return o;
}

nlohmann::json torque_lag_json(const TorqueLagFit& f) {
  nlohmann::json j = {{"done", f.done}};
  if (!f.done) {
    j["why_not"] = f.why_not;
    return j;
  }
  j["significant"] = f.significant;
  j["at_edge"] = f.at_edge;
  j["heldout"] = {{"fold_gain", f.fold_gain}, {"mean", f.test.mean}, {"se", f.test.se}, {"p", f.test.p_value}, {"level", f.alpha}};
  j["lag_s"] = {{"value", f.lag_s.value}, {"ci95", {f.lag_s.lo, f.lag_s.hi}}};
  j["params"] = nlohmann::json::array();
  for (std::size_t i = 0; i < f.params.size(); ++i) {
    auto e = param_json(f.params[i]);
    e["value_without_lag"] = f.params_no_lag[i].est.value;
    j["params"].push_back(e);
  }
  j["profile"] = {{"lag_s", f.grid_s}, {"sse", f.sse}};
  return j;
}

}  // namespace manip::diagnosis
