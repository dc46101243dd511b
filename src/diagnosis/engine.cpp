#include "manip/diagnosis/engine.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <sstream>

#include "manip/common/errors.hpp"
#include "manip/common/rng.hpp"

namespace manip::diagnosis {

namespace {
// require_physical: a wrong-sign gain beyond its interval that exceeds this
// fraction of the mechanism's largest right-sign gain makes it unphysical.
constexpr double kWrongSignFraction = 0.25;
}  // namespace

const ParamEstimate* Diagnosis::find_final(const std::string& name) const {
  for (const auto& p : final_params)
    if (p.name == name) return &p;
  return nullptr;
}
const ParamEstimate* Diagnosis::find_baseline(const std::string& name) const {
  for (const auto& p : baseline_params)
    if (p.name == name) return &p;
  return nullptr;
}

namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;

using Block = CvBlock;

// Sufficient statistics of a least-squares problem over some samples.
struct Stats {
  MatrixXd G;  // X'X
  VectorXd h;  // X'y
  double yy = 0.0, ysum = 0.0;
  double n = 0.0;
  void zero(Eigen::Index p) {
    G = MatrixXd::Zero(p, p);
    h = VectorXd::Zero(p);
    yy = ysum = n = 0.0;
  }
  void add(const Stats& o, double w = 1.0) {
    G += w * o.G;
    h += w * o.h;
    yy += w * o.yy;
    ysum += w * o.ysum;
    n += w * o.n;
  }
  [[nodiscard]] double sst() const { return n > 0 ? yy - ysum * ysum / n : 0.0; }
};

// Solves the normal equations with Jacobi scaling (columns differ by orders of
// magnitude: acceleration vs a constant); a rank-deficient problem falls back
// to the minimum-norm solution.
VectorXd solve(const MatrixXd& G, const VectorXd& h) {
  const Eigen::Index p = G.rows();
  VectorXd s(p);
  for (Eigen::Index i = 0; i < p; ++i) s(i) = G(i, i) > 0 ? 1.0 / std::sqrt(G(i, i)) : 1.0;
  const MatrixXd Gs = s.asDiagonal() * G * s.asDiagonal();
  const VectorXd hs = s.asDiagonal() * h;
  Eigen::LDLT<MatrixXd> ldlt(Gs);
  VectorXd z;
  if (ldlt.info() == Eigen::Success && ldlt.isPositive() && ldlt.rcond() > 1e-13) {
    z = ldlt.solve(hs);
  } else {
    z = Gs.completeOrthogonalDecomposition().solve(hs);
  }
  return s.asDiagonal() * z;
}

double sse_of(const Stats& st, const VectorXd& th) { return st.yy - 2.0 * th.dot(st.h) + th.dot(st.G * th); }

// Column pointers of the current model for one segment.
struct Model {
  std::vector<const Columns*> extras;
  [[nodiscard]] std::vector<const std::vector<double>*> cols(const Dataset& d, std::size_t seg) const {
    std::vector<const std::vector<double>*> c;
    for (const auto& b : d.segments[seg].base) c.push_back(&b);
    for (const auto* e : extras)
      for (const auto& col : (*e)[seg]) c.push_back(&col);
    return c;
  }
  [[nodiscard]] Eigen::Index p(const Dataset& d) const { return static_cast<Eigen::Index>(cols(d, 0).size()); }
};

double dot(const std::vector<double>& a, const std::vector<double>& b, std::size_t lo, std::size_t hi) {
  const auto n = static_cast<Eigen::Index>(hi - lo);
  return Eigen::Map<const VectorXd>(a.data() + lo, n).dot(Eigen::Map<const VectorXd>(b.data() + lo, n));
}

std::vector<Stats> block_stats(const Dataset& d, const Model& m, const std::vector<Block>& blocks) {
  std::vector<Stats> out(blocks.size());
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    const auto& bl = blocks[b];
    const auto c = m.cols(d, bl.seg);
    const auto p = static_cast<Eigen::Index>(c.size());
    const auto& y = d.segments[bl.seg].y;
    Stats& st = out[b];
    st.zero(p);
    for (Eigen::Index i = 0; i < p; ++i) {
      for (Eigen::Index j = 0; j <= i; ++j)
        st.G(i, j) = st.G(j, i) = dot(*c[static_cast<std::size_t>(i)], *c[static_cast<std::size_t>(j)], bl.begin, bl.end);
      st.h(i) = dot(*c[static_cast<std::size_t>(i)], y, bl.begin, bl.end);
    }
    st.yy = dot(y, y, bl.begin, bl.end);
    st.ysum = std::accumulate(y.begin() + static_cast<long>(bl.begin), y.begin() + static_cast<long>(bl.end), 0.0);
    st.n = static_cast<double>(bl.end - bl.begin);
  }
  return out;
}

// Cross statistics of candidate columns with the current model, per block.
struct CandStats {
  MatrixXd C;  // nc x p   cand' X
  MatrixXd D;  // nc x nc  cand' cand
  VectorXd e;  // nc       cand' y
  void zero(Eigen::Index nc, Eigen::Index p) {
    C = MatrixXd::Zero(nc, p);
    D = MatrixXd::Zero(nc, nc);
    e = VectorXd::Zero(nc);
  }
  void add(const CandStats& o, double w = 1.0) {
    C += w * o.C;
    D += w * o.D;
    e += w * o.e;
  }
};

std::vector<CandStats> cand_stats(const Dataset& d, const Model& m, const std::vector<Block>& blocks, const Columns& cand) {
  std::vector<CandStats> out(blocks.size());
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    const auto& bl = blocks[b];
    const auto c = m.cols(d, bl.seg);
    const auto& k = cand[bl.seg];
    const auto nc = static_cast<Eigen::Index>(k.size());
    const auto p = static_cast<Eigen::Index>(c.size());
    auto& cs = out[b];
    cs.zero(nc, p);
    for (Eigen::Index i = 0; i < nc; ++i) {
      const auto& ki = k[static_cast<std::size_t>(i)];
      for (Eigen::Index j = 0; j < p; ++j) cs.C(i, j) = dot(ki, *c[static_cast<std::size_t>(j)], bl.begin, bl.end);
      for (Eigen::Index j = 0; j <= i; ++j) cs.D(i, j) = cs.D(j, i) = dot(ki, k[static_cast<std::size_t>(j)], bl.begin, bl.end);
      cs.e(i) = dot(ki, d.segments[bl.seg].y, bl.begin, bl.end);
    }
  }
  return out;
}

Stats augment(const Stats& s, const CandStats& c) {
  const Eigen::Index p = s.G.rows(), nc = c.D.rows();
  Stats a;
  a.G.resize(p + nc, p + nc);
  a.G.topLeftCorner(p, p) = s.G;
  a.G.bottomLeftCorner(nc, p) = c.C;
  a.G.topRightCorner(p, nc) = c.C.transpose();
  a.G.bottomRightCorner(nc, nc) = c.D;
  a.h.resize(p + nc);
  a.h << s.h, c.e;
  a.yy = s.yy;
  a.ysum = s.ysum;
  a.n = s.n;
  return a;
}

// Continues the search of a gridded mechanism's shape from a grid point, on
// a lattice kFine times finer than the grid on every axis (its median step;
// log coordinates for an axis of positive values spanning more than a
// factor 4: a frequency, a time constant, a delay range of 20-100 ms). The
// grid is coarse against the ridge of the reflex's error surface, along
// which a longer delay trades against a slower low pass: on synthetic
// reflexes with their truth off the grid the best grid point sat up to
// 10 ms along that ridge from the truth whatever the noise, where a search
// on a grid 16-100 times finer around the truth landed within 0.3-0.8 ms
// of it (docs/diagnosis.md, "Shape estimates and their intervals"). The
// search stays within the grid's range (a shape outside it is refused as
// unphysical elsewhere). Every visited lattice point's per-block statistics
// are kept, so the bootstrap replicates, which search again, reuse them.
class LatticeSearch {
 public:
  static constexpr long kFine = 4;
  struct Result {
    std::vector<double> shape;
    VectorXd th;
    double sse = 0.0;
  };
  LatticeSearch(const Dataset& d, const Mechanism& mech, const Model& fixed, const std::vector<Block>& blocks,
                const std::vector<std::vector<double>>& grid, const std::vector<double>& origin)
      : d_(d), fixed_(fixed), blocks_(blocks), columns_(mech.columns_of(d)) {
    for (std::size_t k = 0; k < origin.size(); ++k) {
      std::vector<double> v;
      for (const auto& g : grid) v.push_back(g[k]);
      std::sort(v.begin(), v.end());
      v.erase(std::unique(v.begin(), v.end()), v.end());
      Axis a;
      a.log = v.front() > 0.0 && v.back() > 4.0 * v.front();
      a.lo = a.u(v.front());
      a.hi = a.u(v.back());
      a.origin = a.u(origin[k]);
      std::vector<double> steps;
      for (std::size_t i = 1; i < v.size(); ++i) steps.push_back(a.u(v[i]) - a.u(v[i - 1]));
      a.h = steps.empty() ? 0.0 : stats::percentile(steps, 50.0) / static_cast<double>(kFine);
      axes_.push_back(a);
    }
  }
  // From the lattice point nearest `start`, with the fixed columns' weighted
  // statistics s (p_fixed parameters) and block weights w.
  Result search(const std::vector<double>& start, const Stats& s, Eigen::Index p_fixed, const std::vector<double>& w) {
    // In the manner of Hooke & Jeeves (1961): an exploratory step to the
    // best of the 3^n - 1 neighbours at distance m, then pattern steps
    // repeating the last move while they help; m starts at one grid step
    // and is halved when no neighbour is better.
    std::vector<long> base = nearest(start);
    Result fb = eval(base, s, p_fixed, w);
    auto explore = [&](std::vector<long> x, Result fx, long m) {
      // Every combination of -m, 0, +m on the searched axes: a diagonal
      // step is taken directly (a ridge across the axes stalls axis steps).
      const std::vector<long> c = x;
      std::vector<long> delta(axes_.size(), -1);
      for (;;) {
        bool zero = true, valid = true;
        std::vector<long> y = c;
        for (std::size_t a = 0; a < axes_.size(); ++a) {
          if (axes_[a].h <= 0.0 && delta[a] != 0) valid = false;
          zero = zero && delta[a] == 0;
          y[a] += m * delta[a];
        }
        if (valid && !zero && inside(y)) {
          Result fy = eval(y, s, p_fixed, w);
          if (fy.sse < fx.sse) {
            x = std::move(y);
            fx = std::move(fy);
          }
        }
        std::size_t a = 0;
        while (a < delta.size() && delta[a] == 1) delta[a++] = -1;
        if (a == delta.size()) break;
        ++delta[a];
      }
      return std::pair{std::move(x), std::move(fx)};
    };
    int moves = 0;
    for (long m = kFine; m >= 1 && moves < kMaxMoves;) {
      auto [x, fx] = explore(base, fb, m);
      if (!(fx.sse < fb.sse)) {
        m /= 2;
        continue;
      }
      while (fx.sse < fb.sse && moves < kMaxMoves) {
        ++moves;
        std::vector<long> p = x;
        for (std::size_t a = 0; a < p.size(); ++a) p[a] += x[a] - base[a];
        base = std::move(x);
        fb = std::move(fx);
        if (!inside(p)) break;
        std::tie(x, fx) = explore(p, eval(p, s, p_fixed, w), m);
      }
    }
    // The reported shape within its lattice step: on each axis the vertex of
    // the parabola through the SSE at the optimum and its two lattice
    // neighbours (the last exploratory steps evaluated them), clamped to
    // half a step; the gains stay the lattice point's. Without it the
    // replicates' percentile interval collapses to one lattice value when
    // they agree on it.
    for (std::size_t a = 0; a < axes_.size(); ++a) {
      if (axes_[a].h <= 0.0) continue;
      std::vector<long> lo = base, hi = base;
      --lo[a];
      ++hi[a];
      if (!inside(lo) || !inside(hi)) continue;
      const double el = eval(lo, s, p_fixed, w).sse, eh = eval(hi, s, p_fixed, w).sse;
      if (!(el >= fb.sse && eh >= fb.sse) || (el == fb.sse && eh == fb.sse)) continue;
      const double v = stats::parabola_vertex(-1.0, el, 0.0, fb.sse, 1.0, eh);
      if (!std::isfinite(v)) continue;
      const double u = axes_[a].origin + (static_cast<double>(base[a]) + std::clamp(v, -0.5, 0.5)) * axes_[a].h;
      fb.shape[a] = axes_[a].v(u);
    }
    return fb;
  }

 private:
  static constexpr int kMaxMoves = 200;
  struct Axis {
    bool log = false;
    double lo = 0.0, hi = 0.0, origin = 0.0, h = 0.0;
    [[nodiscard]] double u(double v) const { return log ? std::log(v) : v; }
    [[nodiscard]] double v(double u_) const { return log ? std::exp(u_) : u_; }
  };
  [[nodiscard]] std::vector<long> nearest(const std::vector<double>& x) const {
    std::vector<long> k(axes_.size(), 0);
    for (std::size_t a = 0; a < axes_.size(); ++a)
      if (axes_[a].h > 0.0) k[a] = std::lround((axes_[a].u(x[a]) - axes_[a].origin) / axes_[a].h);
    return k;
  }
  [[nodiscard]] std::vector<double> setting(const std::vector<long>& k) const {
    std::vector<double> out(axes_.size());
    for (std::size_t a = 0; a < axes_.size(); ++a) out[a] = axes_[a].v(axes_[a].origin + static_cast<double>(k[a]) * axes_[a].h);
    return out;
  }
  [[nodiscard]] bool inside(const std::vector<long>& k) const {
    for (std::size_t a = 0; a < axes_.size(); ++a) {
      const double x = axes_[a].origin + static_cast<double>(k[a]) * axes_[a].h;
      const double tol = 1e-9 * (1.0 + std::fabs(axes_[a].hi - axes_[a].lo));
      if (x < axes_[a].lo - tol || x > axes_[a].hi + tol) return false;
    }
    return true;
  }
  Result eval(const std::vector<long>& k, const Stats& s, Eigen::Index p_fixed, const std::vector<double>& w) {
    auto it = memo_.find(k);
    if (it == memo_.end()) it = memo_.emplace(k, cand_stats(d_, fixed_, blocks_, columns_(setting(k)))).first;
    CandStats c;
    c.zero(it->second.front().D.rows(), p_fixed);
    for (std::size_t b = 0; b < blocks_.size(); ++b)
      if (w[b] > 0) c.add(it->second[b], w[b]);
    const Stats a = augment(s, c);
    Result r;
    r.th = solve(a.G, a.h);
    r.sse = sse_of(a, r.th);
    r.shape = setting(k);
    return r;
  }

  const Dataset& d_;
  const Model& fixed_;
  const std::vector<Block>& blocks_;
  std::function<Columns(std::span<const double>)> columns_;
  std::vector<Axis> axes_;
  std::map<std::vector<long>, std::vector<CandStats>> memo_;
};

template <class T>
T sum_where(const std::vector<T>& v, const std::vector<Block>& blocks, const std::function<bool(const Block&)>& keep,
            const std::function<void(T&)>& zero) {
  T acc;
  zero(acc);
  for (std::size_t b = 0; b < v.size(); ++b)
    if (keep(blocks[b])) acc.add(v[b]);
  return acc;
}

struct FoldEval {
  std::vector<double> sse_test, sst_test;
};

// Held-out evaluation of a fixed-column model.
FoldEval cv_fixed(const std::vector<Stats>& bs, const std::vector<Block>& blocks, int folds, Eigen::Index p) {
  FoldEval fe;
  for (int k = 0; k < folds; ++k) {
    Stats tr, te;
    tr.zero(p);
    te.zero(p);
    for (std::size_t b = 0; b < bs.size(); ++b) (blocks[b].fold == k ? te : tr).add(bs[b]);
    const VectorXd th = solve(tr.G, tr.h);
    fe.sse_test.push_back(sse_of(te, th));
    fe.sst_test.push_back(te.sst());
  }
  return fe;
}

HeldOut held_out(const FoldEval& fe, int reps, PortableRng& rng) {
  HeldOut h;
  const std::size_t k = fe.sse_test.size();
  double sse = 0, sst = 0;
  for (std::size_t i = 0; i < k; ++i) {
    sse += fe.sse_test[i];
    sst += fe.sst_test[i];
    h.fold_vaf.push_back(1.0 - fe.sse_test[i] / fe.sst_test[i]);
  }
  h.vaf.value = 1.0 - sse / sst;
  h.nrmse.value = std::sqrt(sse / sst);
  std::vector<double> vv, nn;
  for (int r = 0; r < reps; ++r) {
    double a = 0, b = 0;
    for (std::size_t i = 0; i < k; ++i) {
      const auto j = static_cast<std::size_t>(rng.below(k));
      a += fe.sse_test[j];
      b += fe.sst_test[j];
    }
    vv.push_back(1.0 - a / b);
    nn.push_back(std::sqrt(a / b));
  }
  h.vaf.lo = stats::percentile(vv, 2.5);
  h.vaf.hi = stats::percentile(vv, 97.5);
  h.nrmse.lo = stats::percentile(nn, 2.5);
  h.nrmse.hi = stats::percentile(nn, 97.5);
  return h;
}

// Concatenated residual of a model over the usable blocks (all of them, in order).
std::vector<double> residual(const Dataset& d, const Model& m, const std::vector<Block>& blocks, const VectorXd& th,
                             std::vector<std::pair<std::size_t, std::size_t>>* where = nullptr) {
  std::vector<double> r;
  for (const auto& bl : blocks) {
    const auto c = m.cols(d, bl.seg);
    const auto& y = d.segments[bl.seg].y;
    for (std::size_t i = bl.begin; i < bl.end; ++i) {
      double v = y[i];
      for (std::size_t j = 0; j < c.size(); ++j) v -= th(static_cast<Eigen::Index>(j)) * (*c[j])[i];
      r.push_back(v);
      if (where) where->emplace_back(bl.seg, i);
    }
  }
  return r;
}

// Misfit signatures of a residual (see docs/diagnosis.md, "Signatures").
Signatures signatures(const Dataset& d, const std::vector<Block>& /*blocks*/, const std::vector<double>& r,
                      const std::vector<std::pair<std::size_t, std::size_t>>& where, double alpha) {
  Signatures s;
  const std::size_t n = r.size();
  double ss = 0;
  for (double v : r) ss += v * v;
  s.resid_rms = std::sqrt(ss / static_cast<double>(n));
  // Decimate to about two samples per smoother bandwidth: neighbouring
  // samples of a smoothed signal are correlated by construction.
  s.decimation = d.smoothing_cutoff_hz > 0 ? std::max(1, static_cast<int>(std::floor(1.0 / (2.0 * d.smoothing_cutoff_hz * d.dt_s)))) : 1;
  const auto q = static_cast<std::size_t>(s.decimation);
  std::vector<double> rd;
  for (std::size_t i = 0; i < n; i += q) rd.push_back(r[i]);
  const double nd = static_cast<double>(rd.size());
  s.skewness = stats::skewness(rd);
  s.skewness_se = std::sqrt(6.0 / nd);
  s.excess_kurtosis = stats::excess_kurtosis(rd);
  s.kurtosis_se = std::sqrt(24.0 / nd);
  s.ljung_box = stats::ljung_box(rd, std::min<int>(20, static_cast<int>(rd.size() / 5)));

  // Autocorrelation of the decimated residual for Bartlett's variance.
  const std::size_t maxlag = std::min<std::size_t>(rd.size() / 4, static_cast<std::size_t>(std::ceil(2.0 / (d.dt_s * static_cast<double>(q)))));
  auto acf = [&](const std::vector<double>& x) {
    const double m = stats::mean(x);
    std::vector<double> a(maxlag + 1, 0.0);
    double c0 = 0;
    for (double v : x) c0 += (v - m) * (v - m);
    for (std::size_t k = 0; k <= maxlag; ++k) {
      double c = 0;
      for (std::size_t i = k; i < x.size(); ++i) c += (x[i] - m) * (x[i - k] - m);
      a[k] = c0 > 0 ? c / c0 : 0.0;
    }
    return a;
  };
  const auto acf_r = acf(rd);

  const double dt = d.dt_s;
  const auto lag_hi = static_cast<std::size_t>(std::lround(0.100 / dt));
  const auto lag_step = std::max<std::size_t>(1, static_cast<std::size_t>(std::lround(0.001 / dt)));
  struct Family {
    std::string name;
    std::function<double(const Segment&, std::size_t)> f;
    bool lagged;
  };
  double t_mid = 0;
  for (const auto& [sg, i] : where) t_mid += d.segments[sg].t0_s + static_cast<double>(i) * dt;
  t_mid /= static_cast<double>(n);
  const double ref = d.pos_ref;
  const std::vector<Family> fam = {
      {"velocity (delayed)", [](const Segment& g, std::size_t i) { return g.vel[i]; }, true},
      {"rectified +velocity (delayed)", [](const Segment& g, std::size_t i) { return std::max(g.vel[i], 0.0); }, true},
      {"rectified -velocity (delayed)", [](const Segment& g, std::size_t i) { return std::min(g.vel[i], 0.0); }, true},
      {"position (delayed)", [](const Segment& g, std::size_t i) { return g.pos[i]; }, true},
      {"position^2", [ref](const Segment& g, std::size_t i) { return (g.pos[i] - ref) * (g.pos[i] - ref); }, false},
      {"sign(velocity)", [](const Segment& g, std::size_t i) { return g.vel[i] > 0 ? 1.0 : (g.vel[i] < 0 ? -1.0 : 0.0); }, false},
      {"acceleration", [](const Segment& g, std::size_t i) { return g.acc[i]; }, false},
      {"time (drift)", [dt, t_mid](const Segment& g, std::size_t i) { return g.t0_s + static_cast<double>(i) * dt - t_mid; }, false},
  };
  for (const auto& f : fam) {
    CrossCorr best;
    best.regressor = f.name;
    const std::size_t nl = f.lagged ? lag_hi / lag_step + 1 : 1;
    double best_abs = -1;
    std::vector<double> x(n);
    for (std::size_t li = 0; li < nl; ++li) {
      const std::size_t lag = li * lag_step;
      for (std::size_t k = 0; k < n; ++k) {
        const auto [sg, i] = where[k];
        x[k] = i >= lag ? f.f(d.segments[sg], i - lag) : 0.0;
      }
      const double mx = stats::mean(x);
      double sxx = 0, sxr = 0;
      for (std::size_t k = 0; k < n; ++k) {
        sxx += (x[k] - mx) * (x[k] - mx);
        sxr += (x[k] - mx) * r[k];
      }
      const double rho = sxx > 0 && ss > 0 ? sxr / std::sqrt(sxx * ss) : 0.0;
      if (std::fabs(rho) > best_abs) {
        best_abs = std::fabs(rho);
        best.rho = rho;
        best.lag_s = static_cast<double>(lag) * dt;
      }
    }
    // Bartlett: var(rho) ~ (1/n) sum_k acf_r(k) acf_x(k), on the decimated series.
    std::vector<double> xd;
    for (std::size_t k = 0; k < n; k += q) {
      const auto [sg, i] = where[k];
      xd.push_back(f.f(d.segments[sg], i));
    }
    const auto acf_x = acf(xd);
    double v = acf_r[0] * acf_x[0];
    for (std::size_t k = 1; k <= maxlag; ++k) v += 2.0 * acf_r[k] * acf_x[k];
    v = std::max(v, 1.0) / nd;
    const double z = stats::norm_isf(alpha / (2.0 * static_cast<double>(nl)));
    best.bound = z * std::sqrt(v);
    best.significant = std::fabs(best.rho) > best.bound;
    s.xcorr.push_back(best);
  }
  return s;
}

// Held-out prediction: fold k's samples predicted by model_of(k) fitted on
// the other folds (NaN outside the blocks).
std::vector<std::vector<double>> heldout_predict(const Dataset& d, const std::vector<Block>& blocks, int folds,
                                                 const std::function<Model(int)>& model_of) {
  std::vector<std::vector<double>> out(d.segments.size());
  for (std::size_t s = 0; s < d.segments.size(); ++s) out[s].assign(d.segments[s].y.size(), std::numeric_limits<double>::quiet_NaN());
  for (int k = 0; k < folds; ++k) {
    const Model m = model_of(k);
    const auto bs = block_stats(d, m, blocks);
    Stats tr;
    tr.zero(m.p(d));
    for (std::size_t b = 0; b < blocks.size(); ++b)
      if (blocks[b].fold != k) tr.add(bs[b]);
    const VectorXd th = solve(tr.G, tr.h);
    for (const auto& bl : blocks) {
      if (bl.fold != k) continue;
      const auto c = m.cols(d, bl.seg);
      for (std::size_t i = bl.begin; i < bl.end; ++i) {
        double v = 0.0;
        for (std::size_t j = 0; j < c.size(); ++j) v += th(static_cast<Eigen::Index>(j)) * (*c[j])[i];
        out[bl.seg][i] = v;
      }
    }
  }
  return out;
}

// Cluster-robust (sandwich) covariance of the least-squares parameters, with
// the clusters given by the blocks' bootstrap units (Liang & Zeger 1986;
// small-sample factor G/(G-1)): V = A^-1 (sum_g s_g s_g') A^-1, A = X'X,
// s_g = X_g'(y_g - X_g theta) = h_g - G_g theta from the per-block statistics.
// Within-trial (or within-block) correlation of the smoothed residual is
// therefore allowed for; only the units are taken as independent.
MatrixXd cluster_covariance(const std::vector<Stats>& bs, const std::vector<Block>& blocks, const VectorXd& th, int& clusters) {
  const Eigen::Index p = th.size();
  std::size_t nu = 0;
  for (const auto& b : blocks) nu = std::max(nu, b.unit + 1);
  std::vector<VectorXd> score(nu, VectorXd::Zero(p));
  std::vector<bool> present(nu, false);
  MatrixXd A = MatrixXd::Zero(p, p);
  for (std::size_t b = 0; b < bs.size(); ++b) {
    score[blocks[b].unit] += bs[b].h - bs[b].G * th;
    present[blocks[b].unit] = true;
    A += bs[b].G;
  }
  MatrixXd meat = MatrixXd::Zero(p, p);
  clusters = 0;
  for (std::size_t u = 0; u < nu; ++u)
    if (present[u]) {
      meat += score[u] * score[u].transpose();
      ++clusters;
    }
  VectorXd s(p);
  for (Eigen::Index i = 0; i < p; ++i) s(i) = A(i, i) > 0 ? 1.0 / std::sqrt(A(i, i)) : 1.0;
  const MatrixXd Ainv = s.asDiagonal() * MatrixXd((s.asDiagonal() * A * s.asDiagonal()).completeOrthogonalDecomposition().pseudoInverse()) *
                        s.asDiagonal();
  const double g = static_cast<double>(clusters);
  return (g > 1 ? g / (g - 1) : 1.0) * Ainv * meat * Ainv;
}

// Bootstrap weights per block: units (blocks, or trials for planar data) drawn
// with replacement; a block's weight is the count of its unit.
std::vector<std::vector<double>> multinomial_weights(const std::vector<Block>& blocks, int reps, PortableRng& rng) {
  std::size_t nu = 0;
  for (const auto& b : blocks) nu = std::max(nu, b.unit + 1);
  std::vector<std::vector<double>> w(static_cast<std::size_t>(reps), std::vector<double>(blocks.size(), 0.0));
  std::vector<double> count(nu);
  for (auto& row : w) {
    std::fill(count.begin(), count.end(), 0.0);
    for (std::size_t i = 0; i < nu; ++i) count[static_cast<std::size_t>(rng.below(nu))] += 1.0;
    for (std::size_t b = 0; b < blocks.size(); ++b) row[b] = count[blocks[b].unit];
  }
  return w;
}

}  // namespace

std::vector<CvBlock> cv_blocks(const Dataset& d, const EngineOptions& opt, std::size_t history) {
  std::vector<Block> blocks;
  const int K = opt.folds;
  const auto nseg = d.segments.size();
  if (nseg == 0) throw InputError(d.source + ": no data");
  // Units: a segment's group (planar: the trial, both axes), else the segment itself.
  std::vector<int> unit_key(nseg);
  for (std::size_t s = 0; s < nseg; ++s) unit_key[s] = d.segments[s].group >= 0 ? d.segments[s].group : -1 - static_cast<int>(s);
  std::vector<int> keys(unit_key);
  std::sort(keys.begin(), keys.end());
  keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
  const bool grouped = std::any_of(d.segments.begin(), d.segments.end(), [](const Segment& g) { return g.group >= 0; });
  if (grouped && keys.size() < static_cast<std::size_t>(K))
    throw InputError(d.source + ": " + std::to_string(keys.size()) + " usable trials: " + std::to_string(K) +
                     "-fold cross-validation over trials needs at least " + std::to_string(K));
  if (keys.size() >= static_cast<std::size_t>(K)) {  // segments (trials) are the units; folds group neighbours
    // Units in order of first appearance (time order), folds of neighbouring units.
    std::vector<std::size_t> rank(nseg);
    std::vector<int> order;
    for (std::size_t s = 0; s < nseg; ++s) {
      auto it = std::find(order.begin(), order.end(), unit_key[s]);
      if (it == order.end()) {
        order.push_back(unit_key[s]);
        it = order.end() - 1;
      }
      rank[s] = static_cast<std::size_t>(it - order.begin());
    }
    const std::size_t nu = order.size();
    for (std::size_t s = 0; s < nseg; ++s) {
      const auto& g = d.segments[s];
      if (g.first + history >= g.last)
        throw InputError(d.source + ": segment " + std::to_string(s) + " shorter than the " +
                         std::to_string(static_cast<double>(history) * d.dt_s) + " s of history the mechanisms need");
      blocks.push_back({s, g.first + history, g.last, static_cast<int>(rank[s] * static_cast<std::size_t>(K) / nu), rank[s]});
    }
    return blocks;
  }
  if (nseg != 1)
    throw InputError(d.source + ": " + std::to_string(nseg) + " segments: cross-validation needs one continuous record or at least " +
                     std::to_string(K) + " segments");
  const auto& g = d.segments[0];
  const auto guard = static_cast<std::size_t>(std::ceil(opt.guard_s / d.dt_s));
  const auto minfold = static_cast<std::size_t>(std::ceil(opt.min_fold_s / d.dt_s));
  const std::size_t lo = g.first + history;
  const double need_s = static_cast<double>(history + static_cast<std::size_t>(K) * (minfold + guard) + (g.y.size() - g.last) + g.first) * d.dt_s;
  if (lo >= g.last || (g.last - lo) < static_cast<std::size_t>(K) * (minfold + guard))
  {
    char msg[160];
    std::snprintf(msg, sizeof msg, ": record too short for %d-fold cross-validation: %.1f s, need at least %.1f s", K,
                  static_cast<double>(g.y.size()) * d.dt_s, need_s);
    throw InputError(d.source + msg);
  }
  const std::size_t L = g.last - lo;
  for (int k = 0; k < K; ++k) {
    std::size_t a = lo + L * static_cast<std::size_t>(k) / static_cast<std::size_t>(K);
    std::size_t b = lo + L * static_cast<std::size_t>(k + 1) / static_cast<std::size_t>(K);
    if (k > 0) a += guard / 2;
    if (k < K - 1) b -= (guard + 1) / 2;
    const auto m = static_cast<std::size_t>(opt.blocks_per_fold);
    for (std::size_t j = 0; j < m; ++j)
      blocks.push_back({0, a + (b - a) * j / m, a + (b - a) * (j + 1) / m, k, blocks.size()});
  }
  return blocks;
}

Fit fit_full(const Dataset& d, const std::vector<const Columns*>& extras, std::size_t skip) {
  Model m{extras};
  std::vector<Block> blocks;
  for (std::size_t s = 0; s < d.segments.size(); ++s)
    blocks.push_back({s, d.segments[s].first + skip, d.segments[s].last, 0});
  const auto bs = block_stats(d, m, blocks);
  Stats t;
  t.zero(m.p(d));
  for (const auto& b : bs) t.add(b);
  Fit f;
  f.theta = solve(t.G, t.h);
  f.sse = sse_of(t, f.theta);
  f.sst = t.sst();
  f.n = static_cast<std::size_t>(t.n);
  return f;
}

Diagnosis diagnose(const Dataset& d, const std::vector<std::unique_ptr<Mechanism>>& lib, const EngineOptions& opt) {
  const auto t_start = std::chrono::steady_clock::now();
  auto say = [&](const std::string& s) {
    if (opt.progress) opt.progress(s);
  };
  if (opt.folds < 3) throw UsageError("diagnosis: need at least 3 folds");
  Diagnosis out;
  out.source = d.source;
  std::size_t history = 0;
  for (const auto& m : lib)
    if (m->not_applicable(d).empty()) history = std::max(history, m->history_samples(d));
  const auto blocks = cv_blocks(d, opt, history);
  out.folds = opt.folds;
  out.blocks = static_cast<int>(blocks.size());
  out.guard_s = opt.guard_s;
  for (const auto& b : blocks) out.n_used += b.end - b.begin;
  out.duration_s = static_cast<double>(out.n_used) * d.dt_s;
  PortableRng rng(opt.seed);

  // --- baseline
  say("baseline fit (" + std::to_string(out.n_used) + " samples, " + std::to_string(opt.folds) + " folds)");
  Model model;
  const Eigen::Index p0 = model.p(d);
  auto bs_base = block_stats(d, model, blocks);
  Stats all;
  all.zero(p0);
  for (const auto& b : bs_base) all.add(b);
  const VectorXd th0 = solve(all.G, all.h);
  FoldEval fe_base = cv_fixed(bs_base, blocks, opt.folds, p0);
  out.baseline_heldout = held_out(fe_base, opt.bootstrap, rng);
  {
    std::vector<std::pair<std::size_t, std::size_t>> where;
    const auto r = residual(d, model, blocks, th0, &where);
    say("misfit signatures of the baseline");
    out.before = signatures(d, blocks, r, where, opt.alpha);
  }

  // --- greedy search
  std::vector<Columns> accepted_cols;  // owned; model.extras points into it (reserved: no reallocation)
  accepted_cols.reserve(lib.size());
  std::vector<std::size_t> accepted_idx;
  FoldEval fe_cur = fe_base;
  std::vector<bool> used(lib.size(), false);
  std::vector<std::size_t> last_fold_setting;  // per fold: the last accepted mechanism's grid index chosen on the training folds
  for (std::size_t round = 0; round < lib.size(); ++round) {
    Round rd;
    const Eigen::Index p = model.p(d);
    auto bs = block_stats(d, model, blocks);
    std::vector<Stats> tr_fold(static_cast<std::size_t>(opt.folds)), te_fold(static_cast<std::size_t>(opt.folds));
    for (int k = 0; k < opt.folds; ++k) {
      auto& tr = tr_fold[static_cast<std::size_t>(k)];
      auto& te = te_fold[static_cast<std::size_t>(k)];
      tr.zero(p);
      te.zero(p);
      for (std::size_t b = 0; b < bs.size(); ++b) (blocks[b].fold == k ? te : tr).add(bs[b]);
    }
    Stats tot;
    tot.zero(p);
    for (const auto& b : bs) tot.add(b);
    std::vector<std::size_t> cand_lib;
    std::vector<std::vector<double>> cand_fold_sse;
    std::vector<std::vector<std::size_t>> cand_fold_setting;
    for (std::size_t mi = 0; mi < lib.size(); ++mi) {
      if (used[mi]) continue;
      const auto& mech = *lib[mi];
      CandidateScore cs;
      cs.id = mech.id();
      cs.title = mech.title();
      cs.signature = mech.signature();
      cs.not_applicable = mech.not_applicable(d);
      if (!cs.not_applicable.empty()) {
        rd.candidates.push_back(cs);
        continue;
      }
      say("round " + std::to_string(round + 1) + ": scoring " + cs.id);
      const auto grid = mech.grid(d);
      // Per setting: train/test stats per fold (sums of the per-block cross statistics).
      std::vector<double> best_tr(static_cast<std::size_t>(opt.folds), std::numeric_limits<double>::infinity());
      std::vector<std::size_t> best_fold_s(static_cast<std::size_t>(opt.folds), 0);
      std::vector<double> best_te_sse(static_cast<std::size_t>(opt.folds), 0.0);
      double best_all = std::numeric_limits<double>::infinity();
      std::size_t best_all_s = 0;
      VectorXd best_all_th;
      mech.for_each_setting(d, [&](std::size_t s, const Columns& cols) {
        const auto cb = cand_stats(d, model, blocks, cols);
        const Eigen::Index nc = cb.front().D.rows();
        CandStats ctot;
        ctot.zero(nc, p);
        std::vector<CandStats> cfold(static_cast<std::size_t>(opt.folds));
        for (auto& c : cfold) c.zero(nc, p);
        for (std::size_t b = 0; b < cb.size(); ++b) {
          ctot.add(cb[b]);
          cfold[static_cast<std::size_t>(blocks[b].fold)].add(cb[b]);
        }
        const Stats aall = augment(tot, ctot);
        const VectorXd th = solve(aall.G, aall.h);
        const double sse_all = sse_of(aall, th);
        if (sse_all < best_all) {
          best_all = sse_all;
          best_all_s = s;
          best_all_th = th;
        }
        for (int k = 0; k < opt.folds; ++k) {
          const auto ku = static_cast<std::size_t>(k);
          CandStats ctr = ctot;
          ctr.add(cfold[ku], -1.0);
          const Stats atr = augment(tr_fold[ku], ctr);
          const VectorXd tk = solve(atr.G, atr.h);
          const double sse_tr = sse_of(atr, tk);
          if (sse_tr < best_tr[ku]) {
            best_tr[ku] = sse_tr;
            best_fold_s[ku] = s;
            best_te_sse[ku] = sse_of(augment(te_fold[ku], cfold[ku]), tk);
          }
        }
      });
      for (int k = 0; k < opt.folds; ++k) {
        const auto ku = static_cast<std::size_t>(k);
        cs.fold_gain.push_back((fe_cur.sse_test[ku] - best_te_sse[ku]) / fe_cur.sse_test[ku]);
      }
      cs.test = stats::one_sided_t(cs.fold_gain);
      cs.setting = grid[best_all_s];
      if (grid.size() > 1 && static_cast<std::size_t>(mech.main_param()) < cs.setting.size())
        for (const auto s : best_fold_s) cs.fold_main.push_back(grid[s][static_cast<std::size_t>(mech.main_param())]);
      const auto sp = mech.shape_params();
      for (std::size_t i = 0; i < sp.size(); ++i)
        cs.params.push_back({sp[i].name, sp[i].unit, {cs.setting[i], cs.setting[i], cs.setting[i]}, sp[i].plausible_lo, sp[i].plausible_hi, true, true});
      const auto gs = mech.gains();
      for (std::size_t i = 0; i < gs.size(); ++i) {
        const double v = best_all_th(p + static_cast<Eigen::Index>(i));
        cs.params.push_back({gs[i].name, gs[i].unit, {v, v, v}, gs[i].plausible_lo, gs[i].plausible_hi, true});
      }
      {
        const auto cb = cand_stats(d, model, blocks, mech.columns(d, cs.setting));
        std::vector<Stats> ab;
        ab.reserve(bs.size());
        for (std::size_t b = 0; b < bs.size(); ++b) ab.push_back(augment(bs[b], cb[b]));
        const MatrixXd V = cluster_covariance(ab, blocks, best_all_th, cs.clusters);
        for (std::size_t i = 0; i < gs.size(); ++i) {
          const auto j = p + static_cast<Eigen::Index>(i);
          cs.gain_se.push_back(std::sqrt(std::max(V(j, j), 0.0)));
        }
      }
      cand_lib.push_back(mi);
      cand_fold_sse.push_back(best_te_sse);
      cand_fold_setting.push_back(best_fold_s);
      rd.candidates.push_back(cs);
    }
    // Holm over the applicable candidates of this round.
    std::vector<double> pv;
    std::vector<std::size_t> where;
    for (std::size_t i = 0; i < rd.candidates.size(); ++i)
      if (rd.candidates[i].not_applicable.empty()) {
        pv.push_back(rd.candidates[i].test.p_value);
        where.push_back(i);
      }
    const auto adj = stats::holm_adjust(pv);
    {
      // Power 90 % at the Bonferroni level of the round (Holm's first step).
      const double z = stats::norm_isf(opt.alpha / static_cast<double>(std::max<std::size_t>(where.size(), 1))) + stats::norm_isf(0.10);
      for (const auto w : where) {
        auto& c = rd.candidates[w];
        c.gain_mde.clear();
        for (const double se : c.gain_se) c.gain_mde.push_back(z * se);
      }
    }
    int winner = -1;
    double best_gain = 0;
    std::size_t winner_c = 0;
    for (std::size_t j = 0; j < where.size(); ++j) {
      auto& c = rd.candidates[where[j]];
      c.p_holm = adj[j];
      c.significant = adj[j] < opt.alpha && c.test.mean > 0;
      if (opt.require_plausible)
        for (const auto& pp : c.params)
          if (!pp.plausible() || pp.at_edge()) c.implausible = true;
      if (opt.require_physical && !c.params.empty()) {
        const auto& mech = *lib[cand_lib[j]];
        const auto n_shape = mech.shape_params().size();
        const auto main = static_cast<std::size_t>(mech.main_param());
        if (main < n_shape && main < c.params.size() && c.params[main].at_edge()) c.implausible = true;
        // The sign only: a gain's size bound is a guess for some mechanisms
        // (K2), its sign is physics (a reflex resists stretch, friction
        // opposes motion).
        bool some_gain = false;
        for (std::size_t g = n_shape; g < c.params.size(); ++g) {
          const auto& q = c.params[g];
          some_gain = some_gain || !q.has_bounds || ((q.plausible_lo < 0.0 || q.est.value >= 0.0) && (q.plausible_hi > 0.0 || q.est.value <= 0.0));
        }
        if (!some_gain && c.params.size() > n_shape) c.implausible = true;
        // Nor may a gain have the wrong sign beyond its uncertainty (its
        // 95 % Wald interval, cluster-robust SE, entirely on the wrong side)
        // while being more than a quarter of the largest right-sign gain of
        // the same mechanism: a "reflex" that clearly assists stretch in one
        // direction about as much as it resists it in the other is a
        // direction-blind term, not a stretch reflex. A true reflex's
        // unstretched gain leaks a little below 0 when its low pass is off
        // the grid: at most 0.16 of the stretched gain in 59 named
        // synthetic reflexes (docs/diagnosis.md, "Detection study").
        double right = 0.0;
        for (std::size_t g = n_shape; g < c.params.size(); ++g) {
          const auto& q = c.params[g];
          if (q.has_bounds && ((q.plausible_lo >= 0.0 && q.est.value > 0.0) || (q.plausible_hi <= 0.0 && q.est.value < 0.0)))
            right = std::max(right, std::fabs(q.est.value));
        }
        for (std::size_t g = n_shape; g < c.params.size(); ++g) {
          const auto k = g - n_shape;
          const auto& q = c.params[g];
          if (!q.has_bounds || k >= c.gain_se.size()) continue;
          const double half = 1.96 * c.gain_se[k];
          const bool wrong = (q.plausible_lo >= 0.0 && q.est.value + half < 0.0) || (q.plausible_hi <= 0.0 && q.est.value - half > 0.0);
          if (wrong && std::fabs(q.est.value) > kWrongSignFraction * right) c.implausible = true;
        }
      }
      const double score = opt.rank_by_t ? c.test.t : c.test.mean;
      if (c.significant && !c.implausible && (winner < 0 || score > best_gain)) {
        winner = static_cast<int>(where[j]);
        best_gain = score;
        winner_c = j;
      }
    }
    if (opt.prefer_simpler && winner >= 0) {
      const auto& best = rd.candidates[static_cast<std::size_t>(winner)];
      auto n_free = [&](std::size_t j) { return lib[cand_lib[j]]->shape_params().size() + lib[cand_lib[j]]->gains().size(); };
      std::size_t pick = winner_c;
      for (std::size_t j = 0; j < where.size(); ++j) {
        const auto& c = rd.candidates[where[j]];
        if (j == winner_c || !c.significant || c.implausible) continue;
        std::vector<double> diff;
        for (std::size_t k = 0; k < c.fold_gain.size(); ++k) diff.push_back(best.fold_gain[k] - c.fold_gain[k]);
        const auto t = stats::one_sided_t(diff);
        const bool equivalent = t.mean <= t.se;
        const bool simpler = n_free(j) < n_free(pick) ||
                             (n_free(j) == n_free(pick) && (opt.rank_by_t ? c.test.t : c.test.mean) > (opt.rank_by_t ? rd.candidates[where[pick]].test.t : rd.candidates[where[pick]].test.mean));
        if (equivalent && simpler) pick = j;
      }
      winner_c = pick;
      winner = static_cast<int>(where[pick]);
    }
    rd.accepted = winner;
    if (winner < 0) {
      out.rounds.push_back(std::move(rd));
      say("round " + std::to_string(round + 1) + ": no significant held-out gain; stop");
      break;
    }
    const std::size_t mi = cand_lib[winner_c];
    const auto& wc = rd.candidates[static_cast<std::size_t>(winner)];
    say("round " + std::to_string(round + 1) + ": accepted " + wc.id);
    used[mi] = true;
    accepted_idx.push_back(mi);
    out.accepted.push_back(wc.id);
    out.accepted_settings.push_back(wc.setting);
    accepted_cols.push_back(lib[mi]->columns(d, wc.setting));
    model.extras.push_back(&accepted_cols.back());
    fe_cur.sse_test = cand_fold_sse[winner_c];
    last_fold_setting = cand_fold_setting[winner_c];
    out.rounds.push_back(std::move(rd));
  }

  if (opt.keep_predictions) {
    for (const auto& b : blocks) out.predictions.spans.push_back({b.seg, b.begin, b.end, b.fold});
    out.predictions.baseline = heldout_predict(d, blocks, opt.folds, [](int) { return Model{}; });
    if (!accepted_idx.empty()) {
      // The last accepted mechanism with its shape chosen per fold (its fold
      // gains were scored so), the earlier ones at their full-data shape.
      const auto& last = *lib[accepted_idx.back()];
      const auto grid = last.grid(d);
      std::map<std::size_t, Columns> per_setting;
      for (const auto s : last_fold_setting)
        if (!per_setting.count(s)) per_setting.emplace(s, last.columns(d, grid[s]));
      out.predictions.extended = heldout_predict(d, blocks, opt.folds, [&](int k) {
        Model m;
        for (std::size_t a = 0; a + 1 < accepted_cols.size(); ++a) m.extras.push_back(&accepted_cols[a]);
        m.extras.push_back(&per_setting.at(last_fold_setting[static_cast<std::size_t>(k)]));
        return m;
      });
    }
  }

  // --- final model, held-out gain
  out.final_heldout = held_out(fe_cur, 0, rng);
  {
    std::vector<double> gv, vv, nn;
    for (int r = 0; r < opt.bootstrap; ++r) {
      double a = 0, b = 0, c = 0;
      for (int i = 0; i < opt.folds; ++i) {
        const auto j = static_cast<std::size_t>(rng.below(static_cast<std::uint64_t>(opt.folds)));
        a += fe_cur.sse_test[j];
        b += fe_base.sse_test[j];
        c += fe_cur.sst_test[j];
      }
      gv.push_back(1.0 - a / b);
      vv.push_back(1.0 - a / c);
      nn.push_back(std::sqrt(a / c));
    }
    double a = 0, b = 0;
    for (int i = 0; i < opt.folds; ++i) {
      a += fe_cur.sse_test[static_cast<std::size_t>(i)];
      b += fe_base.sse_test[static_cast<std::size_t>(i)];
    }
    out.heldout_gain = {1.0 - a / b, stats::percentile(gv, 2.5), stats::percentile(gv, 97.5)};
    out.final_heldout.vaf.lo = stats::percentile(vv, 2.5);
    out.final_heldout.vaf.hi = stats::percentile(vv, 97.5);
    out.final_heldout.nrmse.lo = stats::percentile(nn, 2.5);
    out.final_heldout.nrmse.hi = stats::percentile(nn, 97.5);
  }

  // --- parameters with block-bootstrap intervals
  say("block bootstrap (" + std::to_string(opt.bootstrap) + " replicates over " + std::to_string(blocks.size()) + " blocks)");
  const auto W = multinomial_weights(blocks, opt.bootstrap, rng);
  auto weighted = [&](const std::vector<Stats>& bs, const std::vector<double>& w, Eigen::Index p) {
    Stats s;
    s.zero(p);
    for (std::size_t b = 0; b < bs.size(); ++b)
      if (w[b] > 0) s.add(bs[b], w[b]);
    return s;
  };
  auto to_interval = [](double v, const std::vector<double>& boot) {
    return Interval{v, stats::percentile(boot, 2.5), stats::percentile(boot, 97.5)};
  };
  {
    std::vector<std::vector<double>> boot(static_cast<std::size_t>(p0));
    for (const auto& w : W) {
      const Stats s = weighted(bs_base, w, p0);
      const VectorXd th = solve(s.G, s.h);
      for (Eigen::Index i = 0; i < p0; ++i) boot[static_cast<std::size_t>(i)].push_back(th(i));
    }
    for (Eigen::Index i = 0; i < p0; ++i)
      out.baseline_params.push_back({d.base_names[static_cast<std::size_t>(i)], d.base_units[static_cast<std::size_t>(i)],
                                     to_interval(th0(i), boot[static_cast<std::size_t>(i)]), 0, 0, false});
  }
  // Each later gridded mechanism (after the first accepted one with a shape
  // grid) gets its shape and the shape's interval from a search of its own
  // in the block-bootstrap replicates, every other accepted mechanism at its
  // named shape. Then the first gridded mechanism has its shape re-searched
  // in the full data and every replicate, the later ones at their shapes so
  // found: every gain, every baseline parameter and their intervals come
  // from these fits, so that the report's parameters all belong to one
  // model, the one whose residual is "what remains" below.
  int gridded = -1;
  for (std::size_t a = 0; a < accepted_idx.size(); ++a)
    if (lib[accepted_idx[a]]->grid(d).size() > 1) {
      gridded = static_cast<int>(a);
      break;
    }
  // The grid point of least weighted SSE against the fixed columns' weighted
  // statistics s (p_fixed parameters), and its solution.
  struct GridFit {
    std::size_t g = 0;
    VectorXd th;
  };
  auto grid_search = [&](const Stats& s, Eigen::Index p_fixed, const std::vector<std::vector<CandStats>>& gstats, const std::vector<double>& w) {
    double best = std::numeric_limits<double>::infinity();
    GridFit found;
    for (std::size_t g = 0; g < gstats.size(); ++g) {
      CandStats c;
      c.zero(gstats[g].front().D.rows(), p_fixed);
      for (std::size_t b = 0; b < blocks.size(); ++b)
        if (w[b] > 0) c.add(gstats[g][b], w[b]);
      const Stats a = augment(s, c);
      VectorXd th = solve(a.G, a.h);
      const double e = sse_of(a, th);
      if (e < best) {
        best = e;
        found = {g, std::move(th)};
      }
    }
    return found;
  };
  // The shape is then searched off the grid (LatticeSearch), in the
  // full-data fit and in every replicate, each from its own best grid
  // point: the reported shape and its gains are those of one setting, and
  // neither the estimate nor its interval is held to the grid's spacing (a
  // percentile interval of grid values collapses to one point when the
  // replicates agree on it). `ls` is built at the first call, its lattice
  // anchored at that call's (the full-data fit's) best grid point; `kept`:
  // the other accepted columns, at their named shapes.
  struct ShapeFit {
    VectorXd th;
    std::vector<double> shape;
  };
  auto search_shape = [&](const Mechanism& mech, const Model& kept, std::optional<LatticeSearch>& ls,
                          const std::vector<std::vector<double>>& gset, const std::vector<std::vector<CandStats>>& gstats,
                          const Stats& s, Eigen::Index p, const std::vector<double>& w) {
    auto f = grid_search(s, p, gstats, w);
    if (!mech.searchable_off_grid()) return ShapeFit{std::move(f.th), gset[f.g]};
    if (!ls) ls.emplace(d, mech, kept, blocks, gset, gset[f.g]);
    auto r = ls->search(gset[f.g], s, p, w);
    return ShapeFit{std::move(r.th), std::move(r.shape)};
  };
  // Shape of each later gridded mechanism: its full-data optimum with the
  // replicates' percentiles, every other accepted mechanism fixed; its
  // columns at that optimum join the fixed ones below.
  std::vector<double> ones(blocks.size(), 1.0), shape_full;
  std::map<std::size_t, std::vector<Interval>> later_shape;
  std::map<std::size_t, Columns> later_cols;
  for (std::size_t a = 0; a < accepted_idx.size(); ++a) {
    const auto& mech = *lib[accepted_idx[a]];
    const auto gset = mech.grid(d);
    if (static_cast<int>(a) == gridded || gset.size() <= 1) continue;
    say("block bootstrap of the " + mech.id() + " shape");
    Model others;
    for (std::size_t o = 0; o < accepted_idx.size(); ++o)
      if (o != a) others.extras.push_back(&accepted_cols[o]);
    const Eigen::Index po = others.p(d);
    const auto bs_o = block_stats(d, others, blocks);
    std::vector<std::vector<CandStats>> gstats(gset.size());
    mech.for_each_setting(d, [&](std::size_t g, const Columns& cols) { gstats[g] = cand_stats(d, others, blocks, cols); });
    std::optional<LatticeSearch> ls;
    auto best_shape = [&](const std::vector<double>& w) {
      return search_shape(mech, others, ls, gset, gstats, weighted(bs_o, w, po), po, w).shape;
    };
    const auto full = best_shape(ones);
    std::vector<std::vector<double>> boot(full.size());
    for (const auto& w : W) {
      const auto sh = best_shape(w);
      for (std::size_t i = 0; i < sh.size(); ++i) boot[i].push_back(sh[i]);
    }
    for (std::size_t i = 0; i < full.size(); ++i) later_shape[a].push_back(to_interval(full[i], boot[i]));
    later_cols.emplace(a, full == out.accepted_settings[a] ? accepted_cols[a] : mech.columns(d, full));
  }
  Model fixed;
  for (std::size_t a = 0; a < accepted_idx.size(); ++a)
    if (static_cast<int>(a) != gridded) {
      const auto lc = later_cols.find(a);
      fixed.extras.push_back(lc != later_cols.end() ? &lc->second : &accepted_cols[a]);
    }
  const Eigen::Index pf = fixed.p(d);
  const auto bs_fixed = block_stats(d, fixed, blocks);
  // Parameter layout: base + fixed extras' gains, then the gridded mechanism's shape + gains.
  std::vector<std::vector<double>> grid_set;
  std::vector<std::vector<CandStats>> grid_stats;
  if (gridded >= 0) {
    const auto& mech = *lib[accepted_idx[static_cast<std::size_t>(gridded)]];
    grid_set = mech.grid(d);
    grid_stats.resize(grid_set.size());
    mech.for_each_setting(d, [&](std::size_t s, const Columns& cols) { grid_stats[s] = cand_stats(d, fixed, blocks, cols); });
  }
  std::optional<LatticeSearch> lattice;
  auto fit_weighted = [&](const std::vector<double>& w, std::vector<double>& shape) {
    const Stats s = weighted(bs_fixed, w, pf);
    if (gridded < 0) return VectorXd(solve(s.G, s.h));
    auto r = search_shape(*lib[accepted_idx[static_cast<std::size_t>(gridded)]], fixed, lattice, grid_set, grid_stats, s, pf, w);
    shape = std::move(r.shape);
    return r.th;
  };
  const VectorXd th_full = fit_weighted(ones, shape_full);
  std::vector<VectorXd> th_boot;
  std::vector<std::vector<double>> shape_boot;
  for (const auto& w : W) {
    std::vector<double> sh;
    th_boot.push_back(fit_weighted(w, sh));
    shape_boot.push_back(sh);
  }
  auto column_interval = [&](Eigen::Index i) {
    std::vector<double> b;
    for (const auto& t : th_boot) b.push_back(t(i));
    return to_interval(th_full(i), b);
  };
  for (Eigen::Index i = 0; i < p0; ++i)
    out.final_params.push_back({d.base_names[static_cast<std::size_t>(i)], d.base_units[static_cast<std::size_t>(i)], column_interval(i), 0, 0, false});
  Eigen::Index col = p0;
  // Column of each accepted mechanism's gains (for Mechanism::base_sum).
  std::vector<Eigen::Index> gain_col(accepted_idx.size(), -1);
  for (std::size_t a = 0; a < accepted_idx.size(); ++a) {
    if (static_cast<int>(a) == gridded) continue;
    gain_col[a] = col;
    const auto sp = lib[accepted_idx[a]]->shape_params();
    const auto ls = later_shape.find(a);
    for (std::size_t i = 0; i < sp.size(); ++i) {
      const double v = out.accepted_settings[a][i];
      const Interval iv = ls != later_shape.end() ? ls->second[i] : Interval{v, v, v};
      out.final_params.push_back({sp[i].name, sp[i].unit, iv, sp[i].plausible_lo, sp[i].plausible_hi, true, true});
    }
    for (const auto& g : lib[accepted_idx[a]]->gains()) {
      out.final_params.push_back({g.name, g.unit, column_interval(col), g.plausible_lo, g.plausible_hi, true});
      ++col;
    }
  }
  if (gridded >= 0) {
    const auto& mech = *lib[accepted_idx[static_cast<std::size_t>(gridded)]];
    gain_col[static_cast<std::size_t>(gridded)] = col;
    const auto sp = mech.shape_params();
    for (std::size_t i = 0; i < sp.size(); ++i) {
      std::vector<double> b;
      for (const auto& s : shape_boot) b.push_back(s[i]);
      out.final_params.push_back({sp[i].name, sp[i].unit, to_interval(shape_full[i], b), sp[i].plausible_lo, sp[i].plausible_hi, true, true});
    }
    for (const auto& g : mech.gains()) {
      out.final_params.push_back({g.name, g.unit, column_interval(col), g.plausible_lo, g.plausible_hi, true});
      ++col;
    }
  }
  for (std::size_t a = 0; a < accepted_idx.size(); ++a) {
    const auto bsum = lib[accepted_idx[a]]->base_sum();
    if (bsum.base.empty()) continue;
    const auto gs = lib[accepted_idx[a]]->gains();
    const auto bi = std::find(d.base_names.begin(), d.base_names.end(), bsum.base);
    const auto gi = std::find_if(gs.begin(), gs.end(), [&](const ParamInfo& g) { return g.name == bsum.gain; });
    if (bi == d.base_names.end() || gi == gs.end()) continue;
    const auto ib = static_cast<Eigen::Index>(bi - d.base_names.begin());
    const auto ig = gain_col[a] + static_cast<Eigen::Index>(gi - gs.begin());
    std::vector<double> b;
    for (const auto& t : th_boot) b.push_back(t(ib) + t(ig));
    out.derived_params.push_back({{bsum.name, d.base_units[static_cast<std::size_t>(ib)], to_interval(th_full(ib) + th_full(ig), b), 0, 0, false}, bsum.base, bsum.meaning});
  }
  // What remains: signatures of the final model's residual, with each
  // accepted mechanism at its reported shape (the search between grid
  // points above; its named grid shape when it has no grid or is not
  // searched off it), so that the residual and each term's share below
  // belong to the parameters the report prints.
  {
    Columns gridded_cols;
    Model final_model;
    for (std::size_t a = 0; a < accepted_idx.size(); ++a) {
      const Columns* c = &accepted_cols[a];
      out.final_settings.push_back(out.accepted_settings[a]);
      if (static_cast<int>(a) == gridded) {
        out.final_settings.back() = shape_full;
        if (shape_full != out.accepted_settings[a]) {
          gridded_cols = lib[accepted_idx[a]]->columns(d, shape_full);
          c = &gridded_cols;
        }
      } else if (const auto lc = later_cols.find(a); lc != later_cols.end()) {
        for (std::size_t i = 0; i < later_shape[a].size(); ++i) out.final_settings.back()[i] = later_shape[a][i].value;
        c = &lc->second;
      }
      final_model.extras.push_back(c);
    }
    const VectorXd th = fit_full(d, final_model.extras, history).theta;
    std::vector<std::pair<std::size_t, std::size_t>> where;
    const auto r = residual(d, final_model, blocks, th, &where);
    out.after = signatures(d, blocks, r, where, opt.alpha);
    // Each accepted term's RMS, and the target's, over the usable blocks.
    auto rms_about_mean = [](const std::vector<double>& x) {
      const double m = stats::mean(x);
      double q = 0;
      for (double v : x) q += (v - m) * (v - m);
      return x.empty() ? 0.0 : std::sqrt(q / static_cast<double>(x.size()));
    };
    std::vector<double> yv;
    for (const auto& bl : blocks)
      for (std::size_t i = bl.begin; i < bl.end; ++i) yv.push_back(d.segments[bl.seg].y[i]);
    out.target_rms = rms_about_mean(yv);
    Eigen::Index c0 = p0;
    for (const auto* cp : final_model.extras) {
      const auto& cols = *cp;
      std::vector<double> term;
      for (const auto& bl : blocks)
        for (std::size_t i = bl.begin; i < bl.end; ++i) {
          double v = 0;
          for (std::size_t j = 0; j < cols[bl.seg].size(); ++j) v += th(c0 + static_cast<Eigen::Index>(j)) * cols[bl.seg][j][i];
          term.push_back(v);
        }
      c0 += static_cast<Eigen::Index>(cols.front().size());
      out.contribution_rms.push_back(rms_about_mean(term));
    }
  }
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  say("done in " + std::to_string(out.seconds) + " s");
  return out;
}

}  // namespace manip::diagnosis
