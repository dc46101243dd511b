#include "manip/dsp/savgol.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

namespace manip::dsp {
namespace {

void validate(int window, int polyorder, int deriv, double delta) {
  if (window < 1 || window % 2 == 0)
    throw std::invalid_argument("savgol: window must be a positive odd integer, got " + std::to_string(window));
  if (polyorder < 0) throw std::invalid_argument("savgol: polyorder must be >= 0");
  if (polyorder >= window)
    throw std::invalid_argument("savgol: polyorder (" + std::to_string(polyorder) + ") must be less than window (" +
                                std::to_string(window) + ")");
  if (deriv < 0) throw std::invalid_argument("savgol: deriv must be >= 0");
  if (!(delta > 0.0) || !std::isfinite(delta)) throw std::invalid_argument("savgol: delta must be finite and > 0");
}

double factorial(int n) {
  double f = 1.0;
  for (int i = 2; i <= n; ++i) f *= i;
  return f;
}

// Least-squares operator of the window: row k of the returned (p+1) x W
// matrix maps the window samples to the coefficient of u^k of the fitted
// polynomial, u = (t - h) / h for t = 0..W-1. Scaling the abscissa to [-1, 1]
// keeps the Vandermonde matrix well conditioned (cond ~ 1e2 for order 5
// instead of ~1e11 for the raw -h..h that scipy factorises), and the thin
// Householder QR (V = QR, pinv(V) = R^-1 Q^T) is backward stable.
Eigen::MatrixXd fit_operator(int window, int polyorder) {
  const int h = window / 2;
  const double scale = h > 0 ? 1.0 / h : 1.0;
  const Eigen::Index w = window, m = polyorder + 1;
  Eigen::MatrixXd v(w, m);
  for (Eigen::Index t = 0; t < w; ++t) {
    const double u = static_cast<double>(t - h) * scale;
    double pk = 1.0;
    for (Eigen::Index k = 0; k < m; ++k) {
      v(t, k) = pk;
      pk *= u;
    }
  }
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(v);
  const Eigen::MatrixXd q = qr.householderQ() * Eigen::MatrixXd::Identity(w, m);
  const Eigen::MatrixXd r = qr.matrixQR().topLeftCorner(m, m).triangularView<Eigen::Upper>();
  return r.triangularView<Eigen::Upper>().solve(q.transpose());
}

// Interior taps w[0..h] in dot order from the fit operator: the deriv-th
// derivative at the centre (u = 0) only involves the u^deriv coefficient,
// times deriv! / (h delta)^deriv. Exact (anti)symmetry is imposed by
// averaging the two mirrored estimates, which the exact solution satisfies.
std::vector<double> centre_taps(const Eigen::MatrixXd& fit, int window, int deriv, double delta) {
  const int h = window / 2;
  const double hs = h > 0 ? h : 1.0;
  const double gain = factorial(deriv) / std::pow(delta, deriv) / std::pow(hs, deriv);
  const double sign = deriv % 2 == 0 ? 1.0 : -1.0;
  std::vector<double> taps(static_cast<std::size_t>(h) + 1);
  taps[0] = deriv % 2 == 0 ? gain * fit(deriv, h) : 0.0;
  for (int k = 1; k <= h; ++k) taps[static_cast<std::size_t>(k)] = 0.5 * gain * (fit(deriv, h + k) + sign * fit(deriv, h - k));
  return taps;
}

// Interior samples: y[i] = w0 x[i] + sum_k w[k] (x[i+k] +- x[i-k]) for i in
// [h, n-h). Folding the (anti)symmetric taps halves the multiplies
// (scipy.ndimage does the same for symmetric kernels). Each block of outputs
// keeps its accumulators in vector registers while the taps stream past, so
// the cost is ~2 vector loads per tap per block; with window 225 this is
// load-bound. Written with GCC/Clang vector extensions because the
// auto-vectoriser shuffled and spilled the plain-array version (355 us per
// 12000 samples vs 2.3 ms for scipy, not enough for the 10x budget).
// Summation order differs from ndimage only at rounding level.
template <class V, int kVecs, bool Even>
[[gnu::always_inline]] inline void convolve_interior_kernel(const double* x, double* y, std::size_t n, std::size_t h,
                                                            const double* w) {
  constexpr std::size_t kL = sizeof(V) / sizeof(double);
  constexpr std::size_t kB = kL * kVecs;
  // memcpy is how unaligned vector loads/stores are spelled portably; the
  // compiler emits plain (v)movupd. No helper returning V by value: that would
  // be an ABI-changing call outside the AVX2 target region.
  const std::size_t end = n - h;
  std::size_t i = h;
  for (; i + kB <= end; i += kB) {
    V acc[kVecs];
    for (int v = 0; v < kVecs; ++v) {
      if constexpr (Even) {
        std::memcpy(&acc[v], x + i + v * kL, sizeof(V));
        acc[v] *= w[0];
      } else {
        acc[v] = V{};
      }
    }
    for (std::size_t k = 1; k <= h; ++k) {
      const V c = V{} + w[k];
      const double* xp = x + i + k;
      const double* xm = x + i - k;
      for (int v = 0; v < kVecs; ++v) {
        V a, b;
        std::memcpy(&a, xp + v * kL, sizeof(V));
        std::memcpy(&b, xm + v * kL, sizeof(V));
        acc[v] += c * (Even ? a + b : a - b);
      }
    }
    for (int v = 0; v < kVecs; ++v) std::memcpy(y + i + v * kL, &acc[v], sizeof(V));
  }
  for (; i < end; ++i) {
    double acc = Even ? w[0] * x[i] : 0.0;
    for (std::size_t k = 1; k <= h; ++k) acc += w[k] * (Even ? x[i + k] + x[i - k] : x[i + k] - x[i - k]);
    y[i] = acc;
  }
}

typedef double V2d __attribute__((vector_size(16)));

template <bool Even>
void convolve_interior_generic(const double* x, double* y, std::size_t n, std::size_t h, const double* w) {
  convolve_interior_kernel<V2d, 4, Even>(x, y, n, h, w);
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
// Same kernel compiled for AVX2 + FMA, chosen at run time: 4 lanes and fused
// multiply-adds halve the time again. The FMA rounds once instead of twice,
// so results differ from the SSE2 path at the last-ulp level only.
#define MANIP_SAVGOL_AVX2 1
typedef double V4d __attribute__((vector_size(32)));

template <bool Even>
__attribute__((target("avx2,fma"))) void convolve_interior_avx2(const double* x, double* y, std::size_t n,
                                                                 std::size_t h, const double* w) {
  convolve_interior_kernel<V4d, 4, Even>(x, y, n, h, w);
}

bool cpu_has_avx2_fma() {
  static const bool has = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return has;
}
#endif

std::atomic<bool> g_allow_avx2{true};

template <bool Even>
void convolve_interior(const double* x, double* y, std::size_t n, std::size_t h, const double* w) {
#ifdef MANIP_SAVGOL_AVX2
  if (g_allow_avx2.load(std::memory_order_relaxed) && cpu_has_avx2_fma())
    return convolve_interior_avx2<Even>(x, y, n, h, w);
#endif
  convolve_interior_generic<Even>(x, y, n, h, w);
}

double smoother_response(const std::vector<double>& taps, double f_norm) {
  // Zero-phase response of the symmetric smoother, f_norm in cycles/sample.
  double hsum = taps[0];
  const double w = 2.0 * std::numbers::pi * f_norm;
  for (std::size_t k = 1; k < taps.size(); ++k) hsum += 2.0 * taps[k] * std::cos(w * static_cast<double>(k));
  return hsum;
}

}  // namespace

std::vector<double> savgol_coeffs(int window, int polyorder, int deriv, double delta) {
  return SavgolFilter(window, polyorder, deriv, delta).coeffs();
}

SavgolFilter::SavgolFilter(int window, int polyorder, int deriv, double delta)
    : window_(window), polyorder_(polyorder), deriv_(deriv), delta_(delta), half_(window / 2), zero_(deriv > polyorder) {
  validate(window, polyorder, deriv, delta);
  const auto h = static_cast<std::size_t>(half_);
  if (zero_) {
    taps_.assign(h + 1, 0.0);
    return;
  }
  const Eigen::MatrixXd fit = fit_operator(window, polyorder);
  taps_ = centre_taps(fit, window, deriv, delta);

  const auto m = static_cast<std::size_t>(polyorder + 1);
  fit_.resize(m * static_cast<std::size_t>(window));
  for (std::size_t k = 0; k < m; ++k)
    for (std::size_t t = 0; t < static_cast<std::size_t>(window); ++t)
      fit_[k * static_cast<std::size_t>(window) + t] = fit(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(t));

  // d^d/dt^d u^k = k!/(k-d)! u^(k-d) / h^d, then / delta^d as scipy's
  // polyval(polyder(fit), i) / delta**deriv.
  const double hs = half_ > 0 ? half_ : 1.0;
  const double chain = 1.0 / std::pow(delta, deriv) / std::pow(hs, deriv);
  auto eval_row = [&](double u, double* row) {
    for (std::size_t k = 0; k < m; ++k) {
      const int ki = static_cast<int>(k);
      if (ki < deriv) {
        row[k] = 0.0;
        continue;
      }
      double fall = 1.0;
      for (int j = ki - deriv + 1; j <= ki; ++j) fall *= j;
      row[k] = fall * std::pow(u, ki - deriv) * chain;
    }
  };
  eval_left_.resize(h * m);
  eval_right_.resize(h * m);
  for (std::size_t t = 0; t < h; ++t) {
    eval_row((static_cast<double>(t) - hs) / hs, &eval_left_[t * m]);
    eval_row(static_cast<double>(t + 1) / hs, &eval_right_[t * m]);
  }
}

std::vector<double> SavgolFilter::coeffs() const {
  // scipy use='conv': coefficient j multiplies x[i + h - j], i.e. dot-order
  // offset k = h - j; w(-k) = (-1)^deriv w(k).
  const int h = half_;
  std::vector<double> c(static_cast<std::size_t>(window_));
  const double sign = deriv_ % 2 == 0 ? 1.0 : -1.0;
  for (int j = 0; j < window_; ++j) {
    const int k = h - j;
    const double w = taps_[static_cast<std::size_t>(std::abs(k))];
    c[static_cast<std::size_t>(j)] = k >= 0 ? w : sign * w;
  }
  return c;
}

void SavgolFilter::apply(std::span<const double> x, std::span<double> y) const {
  const std::size_t n = x.size();
  const auto w = static_cast<std::size_t>(window_);
  if (n < w)
    throw std::invalid_argument("SavgolFilter::apply: mode 'interp' needs at least window (" + std::to_string(w) +
                                ") samples, got " + std::to_string(n));
  if (y.size() != n)
    throw std::invalid_argument("SavgolFilter::apply: output length " + std::to_string(y.size()) +
                                " != input length " + std::to_string(n));
  {
    std::less<const double*> lt;
    if (lt(x.data(), y.data() + n) && lt(y.data(), x.data() + n))
      throw std::invalid_argument("SavgolFilter::apply: x and y must not overlap");
  }
  if (zero_) {
    std::fill(y.begin(), y.end(), 0.0);
    return;
  }
  const auto h = static_cast<std::size_t>(half_);
  if (deriv_ % 2 == 0)
    convolve_interior<true>(x.data(), y.data(), n, h, taps_.data());
  else
    convolve_interior<false>(x.data(), y.data(), n, h, taps_.data());

  // mode='interp': the first and last h outputs come from one polynomial fit
  // of the first / last window each (scipy _fit_edges_polyfit). The fit
  // coefficients are accumulated one at a time into y so that no scratch is
  // needed.
  const auto m = static_cast<std::size_t>(polyorder_ + 1);
  auto fit_edge = [&](const double* xw, const std::vector<double>& eval, double* yout) {
    std::fill(yout, yout + h, 0.0);
    for (std::size_t k = 0; k < m; ++k) {
      const double* row = &fit_[k * w];
      double a = 0.0;
      for (std::size_t t = 0; t < w; ++t) a += row[t] * xw[t];
      for (std::size_t t = 0; t < h; ++t) yout[t] += eval[t * m + k] * a;
    }
  };
  fit_edge(x.data(), eval_left_, y.data());
  fit_edge(x.data() + (n - w), eval_right_, y.data() + (n - h));
}

namespace detail {
void savgol_allow_avx2(bool allow) { g_allow_avx2.store(allow, std::memory_order_relaxed); }
bool savgol_uses_avx2() {
#ifdef MANIP_SAVGOL_AVX2
  return g_allow_avx2.load(std::memory_order_relaxed) && cpu_has_avx2_fma();
#else
  return false;
#endif
}
}  // namespace detail

double savgol_cutoff_hz(int window, int polyorder, double fs_hz) {
  validate(window, polyorder, 0, 1.0);
  if (!(fs_hz > 0.0) || !std::isfinite(fs_hz)) throw std::invalid_argument("savgol_cutoff_hz: fs must be > 0");
  const std::vector<double> taps = centre_taps(fit_operator(window, polyorder), window, 0, 1.0);
  const double level = 1.0 / std::sqrt(2.0);
  // Step well below the main-lobe width (~fs/window) so the first crossing is
  // not skipped; the crossing lies ~5 (polyorder+1) steps up, so this is cheap.
  const double step = 1.0 / (16.0 * window);
  double lo = 0.0;
  double hi = -1.0;
  for (double f = step; f <= 0.5 + 0.5 * step; f += step) {
    const double fc = std::min(f, 0.5);
    if (smoother_response(taps, fc) < level) {
      hi = fc;
      break;
    }
    lo = fc;
  }
  if (hi < 0.0) return std::numeric_limits<double>::infinity();
  for (int it = 0; it < 200 && hi - lo > 4 * std::numeric_limits<double>::epsilon() * hi; ++it) {
    const double mid = 0.5 * (lo + hi);
    (smoother_response(taps, mid) < level ? hi : lo) = mid;
  }
  return 0.5 * (lo + hi) * fs_hz;
}

int savgol_window_for_cutoff(double fs_hz, double fc_hz, int polyorder) {
  if (!(fs_hz > 0.0) || !std::isfinite(fs_hz)) throw std::invalid_argument("savgol_window_for_cutoff: fs must be > 0");
  if (!(fc_hz > 0.0 && fc_hz < fs_hz / 2.0))
    throw std::invalid_argument("savgol_window_for_cutoff: need 0 < fc < fs/2");
  if (polyorder < 0) throw std::invalid_argument("savgol_window_for_cutoff: polyorder must be >= 0");
  const int w_min = polyorder % 2 == 0 ? polyorder + 1 : polyorder + 2;
  auto window_of = [&](long m) { return static_cast<int>(w_min + 2 * m); };
  auto cutoff = [&](long m) { return savgol_cutoff_hz(window_of(m), polyorder, fs_hz); };
  if (cutoff(0) <= fc_hz) return w_min;
  // Bracket the first window index with cutoff <= fc, then bisect.
  // 2^18 samples is over a minute at 4 kHz (fc ~0.03 Hz for order 5); the
  // design's QR needs window x (polyorder+1) doubles, so stop well before
  // memory becomes an issue.
  constexpr long kMaxWindow = 1L << 18;
  long lo = 0, hi = 1;
  while (cutoff(hi) > fc_hz) {
    lo = hi;
    hi *= 2;
    if (w_min + 2 * hi > kMaxWindow)
      throw std::invalid_argument("savgol_window_for_cutoff: fc too low for windows below 2^18 samples");
  }
  while (hi - lo > 1) {
    const long mid = lo + (hi - lo) / 2;
    (cutoff(mid) > fc_hz ? lo : hi) = mid;
  }
  const double above = cutoff(lo) - fc_hz;  // window_of(lo): cut-off above fc
  const double below = fc_hz - cutoff(hi);  // window_of(hi): at or below fc
  return below <= above ? window_of(hi) : window_of(lo);
}

}  // namespace manip::dsp
