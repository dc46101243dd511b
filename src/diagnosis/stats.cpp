#include "manip/diagnosis/stats.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <utility>

namespace manip::diagnosis::stats {
namespace {

// Continued fraction for I_x(a, b) (modified Lentz; Press et al., Numerical Recipes 3rd ed. §6.4).
double beta_cf(double a, double b, double x) {
  constexpr double tiny = 1e-300;
  constexpr double eps = 1e-15;
  const double qab = a + b, qap = a + 1.0, qam = a - 1.0;
  double c = 1.0;
  double d = 1.0 - qab * x / qap;
  if (std::fabs(d) < tiny) d = tiny;
  d = 1.0 / d;
  double h = d;
  for (int m = 1; m <= 10000; ++m) {
    const double m2 = 2.0 * m;
    double aa = m * (b - m) * x / ((qam + m2) * (a + m2));
    d = 1.0 + aa * d;
    if (std::fabs(d) < tiny) d = tiny;
    c = 1.0 + aa / c;
    if (std::fabs(c) < tiny) c = tiny;
    d = 1.0 / d;
    h *= d * c;
    aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
    d = 1.0 + aa * d;
    if (std::fabs(d) < tiny) d = tiny;
    c = 1.0 + aa / c;
    if (std::fabs(c) < tiny) c = tiny;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::fabs(del - 1.0) < eps) break;
  }
  return h;
}

}  // namespace

double incomplete_beta(double a, double b, double x) {
  if (!(a > 0.0) || !(b > 0.0) || !(x >= 0.0) || !(x <= 1.0))
    throw std::invalid_argument("incomplete_beta: need a, b > 0 and 0 <= x <= 1");
  if (x == 0.0 || x == 1.0) return x;
  const double lbt = std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) + a * std::log(x) +
                     b * std::log1p(-x);
  const double bt = std::exp(lbt);
  if (x < (a + 1.0) / (a + b + 2.0)) return bt * beta_cf(a, b, x) / a;
  return 1.0 - bt * beta_cf(b, a, 1.0 - x) / b;
}

double incomplete_gamma_q(double a, double x) {
  if (!(a > 0.0) || !(x >= 0.0)) throw std::invalid_argument("incomplete_gamma_q: need a > 0, x >= 0");
  if (x == 0.0) return 1.0;
  const double gln = std::lgamma(a);
  if (x < a + 1.0) {  // series for P
    double ap = a, sum = 1.0 / a, del = sum;
    for (int n = 0; n < 100000; ++n) {
      ap += 1.0;
      del *= x / ap;
      sum += del;
      if (std::fabs(del) < std::fabs(sum) * 1e-16) break;
    }
    return 1.0 - sum * std::exp(-x + a * std::log(x) - gln);
  }
  // continued fraction for Q (Lentz)
  constexpr double tiny = 1e-300;
  double b = x + 1.0 - a, c = 1.0 / tiny, d = 1.0 / b, h = d;
  for (int i = 1; i < 100000; ++i) {
    const double an = -i * (i - a);
    b += 2.0;
    d = an * d + b;
    if (std::fabs(d) < tiny) d = tiny;
    c = b + an / c;
    if (std::fabs(c) < tiny) c = tiny;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::fabs(del - 1.0) < 1e-16) break;
  }
  return std::exp(-x + a * std::log(x) - gln) * h;
}

double t_sf(double t, double df) {
  if (!(df > 0.0)) throw std::invalid_argument("t_sf: df must be > 0");
  if (std::isnan(t)) return std::numeric_limits<double>::quiet_NaN();
  if (std::isinf(t)) return t > 0 ? 0.0 : 1.0;
  const double x = df / (df + t * t);
  const double tail = 0.5 * incomplete_beta(0.5 * df, 0.5, x);  // P(|T| > |t|) / 2
  return t >= 0.0 ? tail : 1.0 - tail;
}

double t_isf(double p, double df) {
  if (!(p > 0.0 && p < 0.5)) throw std::invalid_argument("t_isf: need 0 < p < 0.5");
  double lo = 0.0, hi = 1.0;
  while (t_sf(hi, df) > p) hi *= 2.0;
  for (int i = 0; i < 200 && hi - lo > 1e-13 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (t_sf(mid, df) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

double chi2_sf(double x, double k) {
  if (!(k > 0.0)) throw std::invalid_argument("chi2_sf: k must be > 0");
  if (x <= 0.0) return 1.0;
  return incomplete_gamma_q(0.5 * k, 0.5 * x);
}

double norm_sf(double z) { return 0.5 * std::erfc(z / std::sqrt(2.0)); }

double norm_isf(double p) {
  if (!(p > 0.0 && p < 1.0)) throw std::invalid_argument("norm_isf: need 0 < p < 1");
  double lo = -40.0, hi = 40.0;
  for (int i = 0; i < 200 && hi - lo > 1e-14; ++i) {
    const double mid = 0.5 * (lo + hi);
    (norm_sf(mid) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

double mean(std::span<const double> x) {
  if (x.empty()) return 0.0;
  return std::accumulate(x.begin(), x.end(), 0.0) / static_cast<double>(x.size());
}

namespace {
double central_moment(std::span<const double> x, double m, int k) {
  double s = 0.0;
  for (double v : x) s += std::pow(v - m, k);
  return s / static_cast<double>(x.size());
}
}  // namespace

double skewness(std::span<const double> x) {
  const double m = mean(x);
  const double m2 = central_moment(x, m, 2);
  return m2 > 0 ? central_moment(x, m, 3) / std::pow(m2, 1.5) : 0.0;
}

double excess_kurtosis(std::span<const double> x) {
  const double m = mean(x);
  const double m2 = central_moment(x, m, 2);
  return m2 > 0 ? central_moment(x, m, 4) / (m2 * m2) - 3.0 : 0.0;
}

LjungBox ljung_box(std::span<const double> x, int lags) {
  const auto n = static_cast<int>(x.size());
  if (lags < 1 || lags >= n) throw std::invalid_argument("ljung_box: need 1 <= lags < n");
  const double m = mean(x);
  double c0 = 0.0;
  for (double v : x) c0 += (v - m) * (v - m);
  LjungBox out;
  out.lags = lags;
  if (c0 <= 0.0) return out;
  double q = 0.0;
  for (int k = 1; k <= lags; ++k) {
    double ck = 0.0;
    for (int i = k; i < n; ++i) ck += (x[static_cast<std::size_t>(i)] - m) * (x[static_cast<std::size_t>(i - k)] - m);
    const double r = ck / c0;
    q += r * r / (n - k);
  }
  out.q = n * (n + 2.0) * q;
  out.p_value = chi2_sf(out.q, lags);
  return out;
}

double parabola_vertex(double xa, double fa, double xb, double fb, double xc, double fc) {
  const double num = (xb - xa) * (xb - xa) * (fb - fc) - (xb - xc) * (xb - xc) * (fb - fa);
  const double den = (xb - xa) * (fb - fc) - (xb - xc) * (fb - fa);
  if (!(std::fabs(den) > 0)) return std::numeric_limits<double>::quiet_NaN();
  return xb - 0.5 * num / den;
}

OneSidedT one_sided_t(std::span<const double> g) {
  OneSidedT out;
  out.n = static_cast<int>(g.size());
  if (out.n < 2) throw std::invalid_argument("one_sided_t: need at least 2 values");
  out.mean = mean(g);
  double ss = 0.0;
  for (double v : g) ss += (v - out.mean) * (v - out.mean);
  out.se = std::sqrt(ss / (out.n - 1.0) / out.n);
  if (out.se <= 0.0) {
    out.t = out.mean > 0 ? std::numeric_limits<double>::infinity() : 0.0;
    out.p_value = out.mean > 0 ? 0.0 : 1.0;
    return out;
  }
  out.t = out.mean / out.se;
  out.p_value = t_sf(out.t, out.n - 1.0);
  return out;
}

std::vector<double> holm_adjust(std::span<const double> p) {
  const std::size_t m = p.size();
  std::vector<std::size_t> idx(m);
  std::iota(idx.begin(), idx.end(), 0);
  std::stable_sort(idx.begin(), idx.end(), [&](std::size_t a, std::size_t b) { return p[a] < p[b]; });
  std::vector<double> adj(m);
  double running = 0.0;
  for (std::size_t r = 0; r < m; ++r) {
    const double v = std::min(1.0, static_cast<double>(m - r) * p[idx[r]]);
    running = std::max(running, v);
    adj[idx[r]] = running;
  }
  return adj;
}

double percentile(std::vector<double> x, double q) {
  if (x.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(x.begin(), x.end());
  const double pos = q / 100.0 * static_cast<double>(x.size() - 1);
  const auto lo = static_cast<std::size_t>(std::floor(pos));
  const std::size_t hi = std::min(lo + 1, x.size() - 1);
  return x[lo] + (pos - static_cast<double>(lo)) * (x[hi] - x[lo]);
}

ProfileInterval profile_interval(std::span<const double> a, std::span<const double> nll, double level) {
  ProfileInterval out{std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN()};
  std::vector<double> xs, ys;
  for (std::size_t i = 0; i < a.size() && i < nll.size(); ++i)
    if (std::isfinite(a[i]) && std::isfinite(nll[i])) {
      xs.push_back(a[i]);
      ys.push_back(nll[i]);
    }
  if (xs.size() < 3) return out;
  // Least-squares parabola y = c0 + c1 u + c2 u², u = (x − x̄)/s, through
  // every point: the profile's points lie on both sides of the optimum and
  // the closest ones differ by the optimiser's tolerance only.
  const double n = static_cast<double>(xs.size());
  const double xm = std::accumulate(xs.begin(), xs.end(), 0.0) / n;
  double sc = 0.0;
  for (const double x : xs) sc = std::max(sc, std::fabs(x - xm));
  if (!(sc > 0)) return out;
  double m[3][4] = {};
  for (std::size_t i = 0; i < xs.size(); ++i) {
    const double u = (xs[i] - xm) / sc;
    const double r[3] = {1.0, u, u * u};
    for (int p = 0; p < 3; ++p) {
      for (int q = 0; q < 3; ++q) m[p][q] += r[p] * r[q];
      m[p][3] += r[p] * ys[i];
    }
  }
  // Gaussian elimination with partial pivoting on the 3 x 3 normal equations.
  for (int c = 0; c < 3; ++c) {
    int piv = c;
    for (int r = c + 1; r < 3; ++r)
      if (std::fabs(m[r][c]) > std::fabs(m[piv][c])) piv = r;
    if (std::fabs(m[piv][c]) < 1e-12 * n) return out;  // fewer than three distinct abscissae
    for (int k = 0; k < 4; ++k) std::swap(m[c][k], m[piv][k]);
    for (int r = 0; r < 3; ++r) {
      if (r == c) continue;
      const double f = m[r][c] / m[c][c];
      for (int k = c; k < 4; ++k) m[r][k] -= f * m[c][k];
    }
  }
  const double c1 = m[1][3] / m[1][1], c2 = m[2][3] / m[2][2];
  if (!(c2 > 0)) return out;
  const double curv = c2 / (sc * sc);  // in x units
  out.center = xm - 0.5 * c1 / c2 * sc;
  // chi2_1 quantile = z², z the two-sided normal quantile.
  const double z = norm_isf(0.5 * (1.0 - level));
  out.half_width = std::sqrt(z * z / (2.0 * curv));
  return out;
}

RootInterval signed_root_interval(std::span<const double> x, std::span<const double> nll, double level) {
  RootInterval out;
  std::vector<std::pair<double, double>> pt;
  for (std::size_t i = 0; i < x.size() && i < nll.size(); ++i)
    if (std::isfinite(x[i]) && std::isfinite(nll[i])) pt.emplace_back(x[i], nll[i]);
  std::sort(pt.begin(), pt.end());
  // A point profiled twice (the same abscissa): its lower NLL.
  std::vector<std::pair<double, double>> p;
  for (const auto& q : pt)
    if (!p.empty() && q.first == p.back().first)
      p.back().second = std::min(p.back().second, q.second);
    else
      p.push_back(q);
  if (p.size() < 2) return out;
  std::size_t b = 0;
  for (std::size_t i = 1; i < p.size(); ++i)
    if (p[i].second < p[b].second) b = i;
  double xc = p[b].first, fmin = p[b].second;
  if (b > 0 && b + 1 < p.size()) {
    const auto& [xa, fa] = p[b - 1];
    const auto& [xb, fb] = p[b];
    const auto& [xd, fd] = p[b + 1];
    const double v = parabola_vertex(xa, fa, xb, fb, xd, fd);
    // The parabola in Newton's form, f(x) = fb + d1 (x − xb) + c (x − xb)(x − xd),
    // c the second divided difference (its curvature).
    const double d1 = (fd - fb) / (xd - xb), c = (d1 - (fb - fa) / (xb - xa)) / (xd - xa);
    if (std::isfinite(v) && v > xa && v < xd && c > 0) {
      xc = v;
      fmin = std::min(fb, fb + d1 * (v - xb) + c * (v - xb) * (v - xd));
    }
  }
  const double z = norm_isf(0.5 * (1.0 - level));
  auto root = [&](double f) { return std::sqrt(2.0 * std::max(0.0, f - fmin)); };
  // Walk away from the centre on one side (dir +1: increasing x) until the
  // root reaches z; interpolate linearly in the root from the last point short of it.
  auto walk = [&](int dir, double& end, bool& open) {
    double px = xc, pr = 0.0;
    open = true;
    end = xc;
    const auto n = static_cast<std::ptrdiff_t>(p.size());
    for (std::ptrdiff_t k = 0; k < n; ++k) {
      const auto& [xi, fi] = p[static_cast<std::size_t>(dir > 0 ? k : n - 1 - k)];
      if (dir > 0 ? !(xi > xc) : !(xi < xc)) continue;
      const double ri = root(fi);
      if (ri >= z) {
        end = ri > pr ? px + (z - pr) / (ri - pr) * (xi - px) : xi;
        open = false;
        return;
      }
      px = xi;
      pr = ri;
      end = xi;
    }
  };
  walk(+1, out.hi, out.hi_open);
  walk(-1, out.lo, out.lo_open);
  out.valid = true;
  return out;
}

}  // namespace manip::diagnosis::stats
