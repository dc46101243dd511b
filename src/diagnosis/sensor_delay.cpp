#include "manip/diagnosis/sensor_delay.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Dense>

#include "manip/common/rng.hpp"
#include "manip/diagnosis/manipulandum.hpp"
#include "manip/diagnosis/stats.hpp"

namespace manip::diagnosis {
namespace {

// One trial and axis: the disagreement and its columns over the window, each
// with the segment's offset and slope (the isolation's integration
// constants) projected out.
struct Seg {
  std::size_t trial = 0;  // index into the usable trials (the bootstrap unit)
  int axis = 0;
  const PlanarTrial* p = nullptr;
  Eigen::VectorXd q0, q1;                // orthonormal basis of {1, t}
  Eigen::VectorXd e_minus_u;             // e − u_pert (unprojected)
  std::vector<Eigen::VectorXd> z;        // projected shared columns: Δẍ, then friction at each v_s
};

Eigen::VectorXd project(const Seg& s, Eigen::VectorXd v) {
  v -= s.q0 * s.q0.dot(v);
  v -= s.q1 * s.q1.dot(v);
  return v;
}

// I[u_pert](k − τ/dt) of one axis over the window (linear interpolation;
// the series starts u_pert_iso_pre samples before onset).
Eigen::VectorXd delayed_iso(const PlanarTrial& p, int a, std::size_t n, double shift_samples) {
  Eigen::VectorXd out(static_cast<Eigen::Index>(n));
  const auto& I = p.u_pert_iso;
  const double last = static_cast<double>(I.size() - 1);
  for (std::size_t k = 0; k < n; ++k) {
    const double t = std::clamp(static_cast<double>(p.u_pert_iso_pre + k) - shift_samples, 0.0, last);
    const auto k0 = static_cast<std::size_t>(std::floor(t));
    const std::size_t k1 = std::min(k0 + 1, I.size() - 1);
    const double w = t - static_cast<double>(k0);
    out(static_cast<Eigen::Index>(k)) = (1.0 - w) * I[k0](a) + w * I[k1](a);
  }
  return out;
}

// Per trial, at one τ: Σ y², Σ z_j y over its segments (y the projected
// e − u + I[u](· − τ)).
struct TrialStats {
  double yy = 0.0;
  Eigen::VectorXd zy;
};

std::vector<TrialStats> stats_at(const std::vector<Seg>& segs, std::size_t n_trials, std::size_t n_z, double tau_s, double dt) {
  std::vector<TrialStats> st(n_trials, TrialStats{0.0, Eigen::VectorXd::Zero(static_cast<Eigen::Index>(n_z))});
  for (const auto& s : segs) {
    const auto n = static_cast<std::size_t>(s.e_minus_u.size());
    const Eigen::VectorXd y = project(s, s.e_minus_u + delayed_iso(*s.p, s.axis, n, tau_s / dt));
    auto& t = st[s.trial];
    t.yy += y.squaredNorm();
    for (std::size_t j = 0; j < n_z; ++j) t.zy(static_cast<Eigen::Index>(j)) += s.z[j].dot(y);
  }
  return st;
}

// Residual sum of squares with the shared columns `cols` (indices into z),
// trials weighted by `w` (bootstrap counts; empty: 1 each).
double sse(const std::vector<TrialStats>& st, const std::vector<Eigen::MatrixXd>& zz, const std::vector<int>& cols,
           const std::vector<double>& w, Eigen::VectorXd* coef = nullptr) {
  const auto m = static_cast<Eigen::Index>(cols.size());
  double yy = 0.0;
  Eigen::VectorXd zy = Eigen::VectorXd::Zero(m);
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(m, m);
  for (std::size_t i = 0; i < st.size(); ++i) {
    const double wi = w.empty() ? 1.0 : w[i];
    if (wi == 0.0) continue;
    yy += wi * st[i].yy;
    for (Eigen::Index r = 0; r < m; ++r) {
      zy(r) += wi * st[i].zy(cols[static_cast<std::size_t>(r)]);
      for (Eigen::Index c = 0; c < m; ++c) a(r, c) += wi * zz[i](cols[static_cast<std::size_t>(r)], cols[static_cast<std::size_t>(c)]);
    }
  }
  const Eigen::VectorXd b = a.ldlt().solve(zy);
  if (coef) *coef = b;
  return yy - b.dot(zy);
}

// The minimum of f over a grid, refined by the parabola through it and its
// neighbours (kept inside them).
template <class F>
double grid_min(const std::vector<double>& grid, F&& f, double* best_value = nullptr) {
  std::vector<double> v(grid.size());
  for (std::size_t i = 0; i < grid.size(); ++i) v[i] = f(i);
  const auto i = static_cast<std::size_t>(std::min_element(v.begin(), v.end()) - v.begin());
  if (best_value) *best_value = v[i];
  if (i == 0 || i + 1 == grid.size()) return grid[i];
  const double x = stats::parabola_vertex(grid[i - 1], v[i - 1], grid[i], v[i], grid[i + 1], v[i + 1]);
  return std::isfinite(x) ? std::clamp(x, grid[i - 1], grid[i + 1]) : grid[i];
}

}  // namespace

SensorDelay sensor_delay(const Dataset& d, int bootstrap, std::uint64_t seed) {
  SensorDelay out;
  if (!d.is_planar() || !(d.dt_s > 0)) {
    out.why_not = "manipulandum sessions only";
    return out;
  }
  const double dt = d.dt_s;
  // The usable trials: isolated u_pert, a window, a sensor that moved.
  std::vector<Seg> segs;
  std::size_t n_trials = 0, n_fric = 0;
  double force_ss = 0.0, ee = 0.0, track_ss = 0.0;  // ee: Σ of the projected disagreement²
  for (const auto& p : d.planar) {
    const std::size_t n = p.du_ext_adm.size();
    if (n < 8 || p.du_ext_force.size() != n || p.u_pert.size() != n || p.dxdd.size() != n || p.u_pert_iso.size() < n + p.u_pert_iso_pre)
      continue;
    if (n_trials == 0) n_fric = p.friction_iso.size();
    for (const auto& f : p.du_ext_force) force_ss += f.squaredNorm();
    Eigen::VectorXd t(static_cast<Eigen::Index>(n));
    for (std::size_t k = 0; k < n; ++k) t(static_cast<Eigen::Index>(k)) = static_cast<double>(k) * dt;
    for (int a = 0; a < 2; ++a) {
      Seg s;
      s.trial = n_trials;
      s.axis = a;
      s.p = &p;
      const auto ni = static_cast<Eigen::Index>(n);
      s.q0 = Eigen::VectorXd::Constant(ni, 1.0 / std::sqrt(static_cast<double>(n)));
      s.q1 = t - s.q0 * s.q0.dot(t);
      s.q1 /= s.q1.norm();
      s.e_minus_u.resize(ni);
      Eigen::VectorXd acc(ni), e(ni);
      for (std::size_t k = 0; k < n; ++k) {
        const auto kk = static_cast<Eigen::Index>(k);
        e(kk) = p.du_ext_adm[k](a) - p.du_ext_force[k](a);
        s.e_minus_u(kk) = e(kk) - p.u_pert[k](a);
        acc(kk) = p.dxdd[k](a);
      }
      ee += project(s, e).squaredNorm();
      s.z.push_back(project(s, acc));
      for (std::size_t j = 0; j < n_fric; ++j) {
        Eigen::VectorXd f = Eigen::VectorXd::Zero(ni);
        if (j < p.friction_iso.size() && p.friction_iso[j].size() == n)
          for (std::size_t k = 0; k < n; ++k) f(static_cast<Eigen::Index>(k)) = p.friction_iso[j][k](a);
        s.z.push_back(project(s, f));
      }
      Eigen::VectorXd trk = Eigen::VectorXd::Zero(ni);
      if (p.tracking_iso.size() == n)
        for (std::size_t k = 0; k < n; ++k) trk(static_cast<Eigen::Index>(k)) = p.tracking_iso[k](a);
      trk = project(s, trk);
      track_ss += trk.squaredNorm();
      s.z.push_back(std::move(trk));
      segs.push_back(std::move(s));
    }
    ++n_trials;
  }
  if (n_trials < 4) {
    out.why_not = "needs at least 4 perturbed trials with the force sensor and 21 ms before onset, has " + std::to_string(n_trials);
    return out;
  }
  if (!(force_ss > 0.0)) {
    out.why_not = "the force sensor reads a constant (no sensor, or not logged)";
    return out;
  }
  const std::size_t n_z = 2 + n_fric;  // Δẍ, friction at each v_s, tracking
  const int trk = static_cast<int>(1 + n_fric);
  std::vector<Eigen::MatrixXd> zz(n_trials, Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(n_z), static_cast<Eigen::Index>(n_z)));
  for (const auto& s : segs)
    for (std::size_t r = 0; r < n_z; ++r)
      for (std::size_t c = 0; c < n_z; ++c) zz[s.trial](static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) += s.z[r].dot(s.z[c]);

  // Coarse: τ on [−1, 20] ms every 0.1 ms; the columns Δẍ alone, or with
  // the friction column at one v_s. Friction enters only when it removes
  // more than a tenth of the residual with a positive force: a column fits
  // some of anything, and on sessions without friction it would take a
  // share of the delay's.
  std::vector<double> coarse;
  for (int i = -10; i <= static_cast<int>(std::lround(kSensorDelayMaxS / 1e-4)); ++i) coarse.push_back(1e-4 * i);
  std::vector<std::vector<TrialStats>> st_coarse(coarse.size());
  for (std::size_t i = 0; i < coarse.size(); ++i) st_coarse[i] = stats_at(segs, n_trials, n_z, coarse[i], dt);
  std::vector<int> cols = {0};
  double best = 0.0, best_fric = std::numeric_limits<double>::infinity();
  (void)grid_min(coarse, [&](std::size_t i) { return sse(st_coarse[i], zz, cols, {}); }, &best);
  // Tracking first: on a rig whose stages follow the reference through a PD
  // it is most of the disagreement, with a coefficient of 1 (the header).
  if (track_ss > 0.0) {
    const std::vector<int> with = {0, trk};
    double v = 0.0;
    (void)grid_min(coarse, [&](std::size_t i) { return sse(st_coarse[i], zz, with, {}); }, &v);
    if (v < 0.9 * best) {
      out.tracking_share = 1.0 - std::sqrt(std::max(0.0, v) / best);
      cols = with;
      best = v;
    }
  }
  int fric = -1;
  double t_fric = 0.0;
  for (std::size_t j = 0; j < n_fric; ++j) {
    std::vector<int> with = cols;
    with.push_back(static_cast<int>(1 + j));
    double v = 0.0;
    const double t = grid_min(coarse, [&](std::size_t i) { return sse(st_coarse[i], zz, with, {}); }, &v);
    if (v < best_fric) {
      best_fric = v;
      fric = static_cast<int>(j);
      t_fric = t;
    }
  }
  if (fric >= 0 && best_fric < 0.9 * best) {
    // Friction dissipates: a negative force is the column fitting something else.
    std::vector<int> with = cols;
    with.push_back(1 + fric);
    Eigen::VectorXd c;
    (void)sse(stats_at(segs, n_trials, n_z, t_fric, dt), zz, with, {}, &c);
    if (c(c.size() - 1) > 0.0) cols = with;
  }
  const double tau0 = grid_min(coarse, [&](std::size_t i) { return sse(st_coarse[i], zz, cols, {}); });

  // Fine: ±0.4 ms around it every 0.01 ms, per-trial statistics kept for the bootstrap.
  std::vector<double> fine;
  for (int i = -40; i <= 40; ++i) fine.push_back(tau0 + 1e-5 * i);
  std::vector<std::vector<TrialStats>> st_fine(fine.size());
  for (std::size_t i = 0; i < fine.size(); ++i) st_fine[i] = stats_at(segs, n_trials, n_z, fine[i], dt);
  out.tau_s = grid_min(fine, [&](std::size_t i) { return sse(st_fine[i], zz, cols, {}); });
  // The nuisance at the optimum, and how much of the disagreement the fit explains.
  const auto st_opt = stats_at(segs, n_trials, n_z, out.tau_s, dt);
  Eigen::VectorXd coef;
  const double rss = sse(st_opt, zz, cols, {}, &coef);
  out.mass_kg = coef(0);
  for (std::size_t j = 1; j < cols.size(); ++j) {
    const auto c = static_cast<Eigen::Index>(j);
    if (cols[j] == trk) {
      out.tracking_coef = coef(c);
    } else {
      out.friction_n = coef(c);  // e = −I[f_fr] = F I[tanh(v / v_s)]
      if (n_fric == kStageFrictionVs.size()) out.friction_vs_mps = kStageFrictionVs[static_cast<std::size_t>(cols[j] - 1)];
    }
  }
  out.explained_share = ee > 0 ? 1.0 - std::sqrt(std::max(0.0, rss) / ee) : 0.0;
  out.trials = static_cast<int>(n_trials);
  if (out.tracking_share > 0.0) {
    // Held out: the coefficients from the other trials, the residual of the
    // trial left out, y − Z b: yy − 2 bᵀzy + bᵀ zz b over its segments; each
    // model at its own τ (the fit without the column at its optimum).
    std::vector<int> without;
    for (const int c : cols)
      if (c != trk) without.push_back(c);
    const double tau_without = grid_min(coarse, [&](std::size_t i) { return sse(st_coarse[i], zz, without, {}); });
    const auto st_without = stats_at(segs, n_trials, n_z, tau_without, dt);
    auto heldout = [&](const std::vector<TrialStats>& st, const std::vector<int>& use, std::size_t i) {
      std::vector<double> w(n_trials, 1.0);
      w[i] = 0.0;
      Eigen::VectorXd b;
      (void)sse(st, zz, use, w, &b);
      const auto m = static_cast<Eigen::Index>(use.size());
      double r = st[i].yy;
      for (Eigen::Index a = 0; a < m; ++a) {
        r -= 2.0 * b(a) * st[i].zy(use[static_cast<std::size_t>(a)]);
        for (Eigen::Index c = 0; c < m; ++c)
          r += b(a) * b(c) * zz[i](use[static_cast<std::size_t>(a)], use[static_cast<std::size_t>(c)]);
      }
      return r;
    };
    double ss_with = 0.0, ss_without = 0.0;
    for (std::size_t i = 0; i < n_trials; ++i) {
      const double a = heldout(st_opt, cols, i), b = heldout(st_without, without, i);
      ss_with += a;
      ss_without += b;
      if (a < b) ++out.tracking_heldout_better;
    }
    out.tracking_heldout_share = ss_without > 0 ? 1.0 - std::sqrt(std::max(0.0, ss_with) / ss_without) : 0.0;
  }

  // Bootstrap over trials on the fine grid (a replicate's optimum at the
  // grid's edge is kept there: the interval then says "at least this wide").
  std::vector<double> taus;
  PortableRng rng(seed * 0x9E3779B97F4A7C15ull + 0x5D);
  std::vector<double> w(n_trials);
  for (int r = 0; r < bootstrap; ++r) {
    std::fill(w.begin(), w.end(), 0.0);
    for (std::size_t i = 0; i < n_trials; ++i) w[rng.below(n_trials)] += 1.0;
    taus.push_back(grid_min(fine, [&](std::size_t i) { return sse(st_fine[i], zz, cols, w); }));
  }
  out.bootstrap = bootstrap;
  if (!taus.empty()) {
    out.lo_s = stats::percentile(taus, 2.5);
    out.hi_s = stats::percentile(taus, 97.5);
  } else {
    out.lo_s = out.hi_s = out.tau_s;
  }
  out.available = true;
  return out;
}

}  // namespace manip::diagnosis
