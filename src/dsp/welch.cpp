#include "manip/dsp/welch.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <complex>
#include <cstdint>
#include <memory>
#include <numbers>
#include <stdexcept>
#include <string>
#include <unsupported/Eigen/FFT>

// Transcription of scipy 1.10 signal.welch -> csd -> _spectral_helper with
// window='hann', detrend='constant', return_onesided=True, scaling='density',
// average='mean', boundary=None, padded=False.

namespace manip::dsp {
namespace {

// get_window('hann', M) is periodic (fftbins=True): the first M points of a
// symmetric (M+1)-point Hann, computed as general_cosine does,
// 0.5 + 0.5 cos(linspace(-pi, pi, M+1)).
std::vector<double> periodic_hann(std::size_t m) {
  if (m <= 1) return std::vector<double>(m, 1.0);
  const double pi = std::numbers::pi;
  const double step = (pi - (-pi)) / static_cast<double>(m);
  std::vector<double> w(m);
  // The window is symmetric about m/2 (w[m - i] = w[i]): evaluate the first
  // half only (a cos per sample was ~0.2 ms for a 16000-sample trial, computed
  // anew for every trial length). Values differ from scipy's by a few ulp.
  const std::size_t h = m / 2;
  // cos(i step - pi) for i <= h in blocks of kBlock: an exact cos/sin at each
  // block start a, then the angle-sum formula with exact cos/sin of k step,
  // cos(a + k step) = cos a cos k step - sin a sin k step: a few ulp, and
  // 2 cos per block instead of kBlock.
  constexpr std::size_t kBlock = 32;
  double ck[kBlock], sk[kBlock];
  for (std::size_t k = 0; k < kBlock; ++k) {
    ck[k] = std::cos(static_cast<double>(k) * step);
    sk[k] = std::sin(static_cast<double>(k) * step);
  }
  for (std::size_t a = 0; a <= h; a += kBlock) {
    const double ang = static_cast<double>(a) * step + (-pi);
    const double ca = std::cos(ang), sa = std::sin(ang);
    const std::size_t kn = std::min(kBlock, h + 1 - a);
    w[a] = 0.5 + 0.5 * ca;
    for (std::size_t k = 1; k < kn; ++k) w[a + k] = 0.5 + 0.5 * (ca * ck[k] - sa * sk[k]);
  }
  for (std::size_t i = h + 1; i < m; ++i) w[i] = w[m - i];
  return w;
}

// Two fused radix-2 DIF stages on a block of 4q points x0..x3 = x[j + m q]:
//   t0 = x0 + x2, t1 = x0 - x2, t2 = x1 + x3, t3 = x1 - x3, w = W_4q^j,
//   y[j] = t0 + t2, y[j+q] = (t0 - t2) w^2, y[j+2q] = (t1 - i t3) w, y[j+3q] = (t1 + i t3) w^3.
// __restrict on parameters (GCC ignores it on local pointers): the quarters
// are disjoint, and the loop vectorises only when the compiler knows it.
inline __attribute__((always_inline)) void radix4_kernel(double* __restrict r0, double* __restrict i0, double* __restrict r1, double* __restrict i1,
                                                     double* __restrict r2, double* __restrict i2, double* __restrict r3, double* __restrict i3,
                                                     const double* __restrict w1r, const double* __restrict w1i, const double* __restrict w2r,
                                                     const double* __restrict w2i, const double* __restrict w3r, const double* __restrict w3i,
                                                     std::size_t q) {
  for (std::size_t j = 0; j < q; ++j) {
    const double t0r = r0[j] + r2[j], t0i = i0[j] + i2[j];
    const double t1r = r0[j] - r2[j], t1i = i0[j] - i2[j];
    const double t2r = r1[j] + r3[j], t2i = i1[j] + i3[j];
    const double t3r = r1[j] - r3[j], t3i = i1[j] - i3[j];
    r0[j] = t0r + t2r;
    i0[j] = t0i + t2i;
    const double ur = t0r - t2r, ui = t0i - t2i;
    r1[j] = ur * w2r[j] - ui * w2i[j];
    i1[j] = ur * w2i[j] + ui * w2r[j];
    // t1 - i t3 = (t1r + t3i, t1i - t3r); t1 + i t3 = (t1r - t3i, t1i + t3r)
    const double ar = t1r + t3i, ai = t1i - t3r;
    r2[j] = ar * w1r[j] - ai * w1i[j];
    i2[j] = ar * w1i[j] + ai * w1r[j];
    const double br = t1r - t3i, bi = t1i + t3r;
    r3[j] = br * w3r[j] - bi * w3i[j];
    i3[j] = br * w3i[j] + bi * w3r[j];
  }
}

// One radix-4 stage: every block of 4q points of the s-point array. L = 4
// (q = 1) has no twiddles and gets its own loop: a call per 4 points cost more
// than the butterflies.
inline __attribute__((always_inline)) void radix4_stage_kernel(double* re, double* im, std::size_t s, std::size_t q,
                                                               const double* tw) {
  if (q == 1) {
    for (std::size_t i = 0; i < s; i += 4) {
      const double t0r = re[i] + re[i + 2], t0i = im[i] + im[i + 2];
      const double t1r = re[i] - re[i + 2], t1i = im[i] - im[i + 2];
      const double t2r = re[i + 1] + re[i + 3], t2i = im[i + 1] + im[i + 3];
      const double t3r = re[i + 1] - re[i + 3], t3i = im[i + 1] - im[i + 3];
      re[i] = t0r + t2r;
      im[i] = t0i + t2i;
      re[i + 1] = t0r - t2r;
      im[i + 1] = t0i - t2i;
      re[i + 2] = t1r + t3i;
      im[i + 2] = t1i - t3r;
      re[i + 3] = t1r - t3i;
      im[i + 3] = t1i + t3r;
    }
    return;
  }
  for (std::size_t i = 0; i < s; i += 4 * q) {
    double* r = re + i;
    double* m = im + i;
    radix4_kernel(r, m, r + q, m + q, r + 2 * q, m + 2 * q, r + 3 * q, m + 3 * q, tw, tw + q, tw + 2 * q, tw + 3 * q,
                  tw + 4 * q, tw + 5 * q, q);
  }
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
// The same stage compiled for AVX2 (4 lanes instead of SSE2's 2), chosen at
// run time. No FMA: every product and sum rounds as in the SSE2 path, so the
// two give bit-identical results.
__attribute__((target("avx2"))) void radix4_stage_avx2(double* re, double* im, std::size_t s, std::size_t q,
                                                       const double* tw) {
  radix4_stage_kernel(re, im, s, q, tw);
}
bool cpu_has_avx2() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}
#endif

void radix4_stage(double* re, double* im, std::size_t s, std::size_t q, const double* tw) {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  if (cpu_has_avx2()) return radix4_stage_avx2(re, im, s, q, tw);
#endif
  radix4_stage_kernel(re, im, s, q, tw);
}

// One radix-2 DIF stage on two halves a, b of n points: a' = a + b, b' = (a - b) w.
void radix2_stage(double* __restrict ar, double* __restrict ai, double* __restrict br, double* __restrict bi,
                  const double* __restrict wr, const double* __restrict wi, std::size_t n) {
  for (std::size_t j = 0; j < n; ++j) {
    const double dr = ar[j] - br[j], di = ai[j] - bi[j];
    ar[j] += br[j];
    ai[j] += bi[j];
    br[j] = dr * wr[j] - di * wi[j];
    bi[j] = dr * wi[j] + di * wr[j];
  }
}

// b = a * w elementwise on split complex arrays.
void complex_multiply(const double* __restrict ar, const double* __restrict ai, const double* __restrict wr,
                      const double* __restrict wi, double* __restrict br, double* __restrict bi, std::size_t n) {
  for (std::size_t j = 0; j < n; ++j) {
    br[j] = ar[j] * wr[j] - ai[j] * wi[j];
    bi[j] = ar[j] * wi[j] + ai[j] * wr[j];
  }
}

// Complex FFT of a power-of-two size S on split real/imaginary arrays
// (SoA: unit-stride loops that the compiler vectorises; with std::complex GCC
// 12 assembled the butterfly operands through the stack and stalled on store
// forwarding). Decimation in frequency: natural-order input, output in
// bit-reversed order (the caller reads it through rev(), which it has to
// permute anyway; a bit-reversed scatter of the input cost as much as the
// butterflies). Radix-4 stages (half the passes over memory of radix-2,
// 3 twiddle products per 4 points), preceded by one radix-2 stage when log2 S
// is odd. Every twiddle is cos/sin of its exact angle (no recurrences), so the
// error stays ~eps log2(S) of the signal norm; per-stage tables are contiguous
// for a unit-stride inner loop.
class ComplexFftPow2 {
 public:
  explicit ComplexFftPow2(std::size_t s) : s_(s), rev_(s) {
    const double pi = std::numbers::pi;
    std::size_t bits = 0;
    while ((std::size_t{1} << bits) < s_) ++bits;
    for (std::size_t i = 0; i < s_; ++i) {
      std::size_t r = 0;
      for (std::size_t b = 0; b < bits; ++b) r |= ((i >> b) & 1U) << (bits - 1 - b);
      rev_[i] = static_cast<std::uint32_t>(r);
    }
    // Radix-4 stages on blocks of L = S, S/4, ... down to 4 (even log2 S) or 8
    // (odd; a radix-2 stage on blocks of 2 follows).
    // Odd log2 S: one radix-2 stage on the whole array first (its S/2
    // butterflies vectorise fully), then radix-4 stages down to blocks of 4,
    // whose twiddle-free loop is cheap. (Radix-2 last would have meant a
    // radix-4 stage with q = 2 and a scalar pass over pairs, ~20 % slower.)
    radix2_first_ = bits % 2 == 1;
    if (radix2_first_) {
      const std::size_t h = s_ / 2;
      r2_.resize(2 * h);
      for (std::size_t j = 0; j < h; ++j) {
        const double a = -2.0 * pi * static_cast<double>(j) / static_cast<double>(s_);
        r2_[j] = std::cos(a);
        r2_[h + j] = std::sin(a);
      }
    }
    for (std::size_t len = radix2_first_ ? s_ / 2 : s_; len >= 4; len /= 4) {
      Stage st;
      st.len = len;
      st.offset = tw_.size();
      const std::size_t q = len / 4;
      tw_.resize(tw_.size() + 6 * q);
      double* t = tw_.data() + st.offset;
      for (std::size_t j = 0; j < q; ++j) {
        for (std::size_t k = 1; k <= 3; ++k) {
          const double a = -2.0 * pi * static_cast<double>(k * j) / static_cast<double>(len);
          t[(2 * (k - 1)) * q + j] = std::cos(a);
          t[(2 * (k - 1) + 1) * q + j] = std::sin(a);
        }
      }
      stages_.push_back(st);
    }
  }
  [[nodiscard]] std::size_t size() const { return s_; }
  // Output position of frequency k: re[rev()[k]], im[rev()[k]].
  [[nodiscard]] const std::uint32_t* rev() const { return rev_.data(); }

  void transform(double* re, double* im) const {
    if (radix2_first_) {
      // DIF radix-2 on the whole array: x[j] = a + b, x[j + S/2] = (a - b) W_S^j.
      const std::size_t h = s_ / 2;
      radix2_stage(re, im, re + h, im + h, r2_.data(), r2_.data() + h, h);
    }
    for (const Stage& st : stages_) {
      const std::size_t q = st.len / 4;
      radix4_stage(re, im, s_, q, tw_.data() + st.offset);
    }
  }

 private:
  struct Stage {
    std::size_t len, offset;
  };

  std::size_t s_;
  std::vector<std::uint32_t> rev_;
  std::vector<Stage> stages_;
  std::vector<double> tw_;
  bool radix2_first_{false};
  std::vector<double> r2_;  // W_S^j, j < S/2: re then im
};

// Power spectrum |X[k]|^2, k = 0..n/2, of a real sequence of power-of-two
// length n: the n real samples are packed into m = n/2 complex ones
// z[j] = x[2j] + i x[2j+1], transformed, and split into the one-sided spectrum.
//
// Pruning for zero padding: only the first `len` samples are non-zero (the
// estimator pads ~16000-sample trials to 65536), so only J = ceil(len/2) of
// the m complex inputs are. With S the smallest power of two >= J and
// P = m / S, the m-point DFT splits exactly into P DFTs of S points,
//   Z[P q + r] = sum_{j<J} (z[j] W_m^(j r)) W_S^(j q),   r = 0..P-1,
// i.e. the first log2 P stages of a decimation-in-frequency FFT, whose other
// halves are all zero, become one twiddle product per input; and each S-point
// transform works in a cache-sized block.
class RealFftPow2 {
 public:
  explicit RealFftPow2(std::size_t n) : n_(n), m_(n / 2), spr_(m_), spi_(m_), re_(m_), im_(m_) {
    const double pi = std::numbers::pi;
    for (std::size_t k = 0; k < m_; ++k) {
      const double a = -2.0 * pi * static_cast<double>(k) / static_cast<double>(n_);
      spr_[k] = std::cos(a);
      spi_[k] = std::sin(a);
    }
  }
  [[nodiscard]] std::size_t size() const { return n_; }

  // x: the first len <= n samples (the rest are zero). power: n/2 + 1 bins.
  void power(const double* x, std::size_t len, double* power) {
    const std::size_t jn = (len + 1) / 2;  // non-zero complex inputs
    std::size_t s = 1;
    while (s < jn) s *= 2;
    const std::size_t p = m_ / s;
    const Plan& plan = plan_for(s);
    const ComplexFftPow2& fft = *plan.fft;
    double* re = re_.data();
    double* im = im_.data();
    // Block r (at r S) gets z[j] W_m^(j r), zero beyond J.
    const std::size_t jfull = len / 2;  // inputs with both samples present
    for (std::size_t j = 0; j < jfull; ++j) {
      re[j] = x[2 * j];
      im[j] = x[2 * j + 1];
    }
    if (jn > jfull) {
      re[jfull] = x[2 * jfull];
      im[jfull] = 0.0;
    }
    std::fill(re + jn, re + s, 0.0);
    std::fill(im + jn, im + s, 0.0);
    for (std::size_t r = 1; r < p; ++r) {
      double* br = re + r * s;
      double* bi = im + r * s;
      const double* w = plan.pre.data() + 2 * (r - 1) * s;
      complex_multiply(re, im, w, w + s, br, bi, jn);
      std::fill(br + jn, br + s, 0.0);
      std::fill(bi + jn, bi + s, 0.0);
    }
    for (std::size_t r = 0; r < p; ++r) fft.transform(re + r * s, im + r * s);
    // Z[k] for k = P q + r sits at r S + rev[q].
    // Natural order: Z[k], k = P q + r, sits at r S + rev[q] = plan.order[k].
    const std::uint32_t* ord = plan.order.data();
    // X[k] = E[k] + W_n^k O[k], E = (Z[k] + conj Z[m-k]) / 2, O = (Z[k] - conj Z[m-k]) / (2i);
    // and X[m-k] = conj(E[k] - W_n^k O[k]), so each pair (k, m-k) reads Z twice.
    {
      const double z0r = re[ord[0]], z0i = im[ord[0]];
      power[0] = (z0r + z0i) * (z0r + z0i);
      power[m_] = (z0r - z0i) * (z0r - z0i);
    }
    for (std::size_t k = 1; 2 * k <= m_; ++k) {
      const std::size_t a = ord[k], b = ord[m_ - k];
      const double zr = re[a], zi = im[a], cr = re[b], ci = -im[b];
      const double er = 0.5 * (zr + cr), ei = 0.5 * (zi + ci);
      const double o_r = 0.5 * (zi - ci), o_i = -0.5 * (zr - cr);
      const double wor = spr_[k] * o_r - spi_[k] * o_i, woi = spr_[k] * o_i + spi_[k] * o_r;
      const double xr = er + wor, xi = ei + woi;
      power[k] = xr * xr + xi * xi;
      const double yr = er - wor, yi = ei - woi;
      power[m_ - k] = yr * yr + yi * yi;
    }
  }

 private:
  struct Plan {
    std::unique_ptr<ComplexFftPow2> fft;
    // Pruning twiddles W_m^(j r), j < S, for r = 1..P-1: re then im, S each,
    // per r (contiguous, so the product loop vectorises).
    std::vector<double> pre;
    std::vector<std::uint32_t> order;  // where Z[k] is after the P transforms
  };
  const Plan& plan_for(std::size_t s) {
    for (const auto& p : plans_)
      if (p.fft->size() == s) return p;
    Plan pl;
    pl.fft = std::make_unique<ComplexFftPow2>(s);
    const std::size_t p = m_ / s;
    pl.pre.resize(2 * (p - 1) * s);
    for (std::size_t r = 1; r < p; ++r) {
      double* wr = pl.pre.data() + 2 * (r - 1) * s;
      double* wi = wr + s;
      for (std::size_t j = 0; j < s; ++j) {
        // W_m^(j r) = W_n^(2 j r); 2 j r < 2 m, and W_n^(k + m) = -W_n^k.
        const std::size_t k = 2 * j * r;
        const bool hi = k >= m_;
        const std::size_t kk = hi ? k - m_ : k;
        wr[j] = hi ? -spr_[kk] : spr_[kk];
        wi[j] = hi ? -spi_[kk] : spi_[kk];
      }
    }
    const std::uint32_t* rev = pl.fft->rev();
    pl.order.resize(m_);
    for (std::size_t k = 0; k < m_; ++k) pl.order[k] = static_cast<std::uint32_t>((k % p) * s + rev[k / p]);
    plans_.push_back(std::move(pl));
    return plans_.back();
  }
  std::size_t n_, m_;
  std::vector<double> spr_, spi_, re_, im_;
  std::vector<Plan> plans_;  // a few sizes (trial lengths vary)
};

bool is_pow2(std::size_t n) { return n >= 2 && (n & (n - 1)) == 0; }

}  // namespace

void welch(std::span<const double> x, double fs_hz, const WelchOptions& opt, Psd& out) {
  if (!(fs_hz > 0.0) || !std::isfinite(fs_hz)) throw std::invalid_argument("welch: fs must be finite and > 0");
  if (opt.nperseg < 1) throw std::invalid_argument("welch: nperseg must be a positive integer");
  const std::size_t n = x.size();
  if (n == 0) {
    out.f_hz.clear();
    out.pxx.clear();
    return;
  }
  // scipy warns and shrinks nperseg to the input length.
  const std::size_t nperseg = std::min(static_cast<std::size_t>(opt.nperseg), n);
  if (opt.nfft != -1 && (opt.nfft < 1 || static_cast<std::size_t>(opt.nfft) < nperseg))
    throw std::invalid_argument("welch: nfft (" + std::to_string(opt.nfft) +
                                ") must be greater than or equal to nperseg (" + std::to_string(nperseg) + ")");
  const std::size_t nfft = opt.nfft == -1 ? nperseg : static_cast<std::size_t>(opt.nfft);
  if (opt.noverlap < -1) throw std::invalid_argument("welch: noverlap must be >= 0 (or -1 for the default)");
  const std::size_t noverlap = opt.noverlap == -1 ? nperseg / 2 : static_cast<std::size_t>(opt.noverlap);
  if (noverlap >= nperseg) throw std::invalid_argument("welch: noverlap must be less than nperseg");
  const std::size_t step = nperseg - noverlap;
  const std::size_t nseg = (n - noverlap) / step;

  // Per-thread cache: window and its energy, FFT plans (the last power-of-two
  // size; kissfft keeps its own per-length cache) and the work buffers, whose
  // fresh allocation page-faulted on every call for long segments.
  struct Cache {
    std::vector<double> win;
    double win_sq = 0.0;
    std::unique_ptr<RealFftPow2> pow2;
    Eigen::FFT<double> kiss;
    std::vector<double> seg, power;
    std::vector<std::complex<double>> spec;
  };
  thread_local Cache c;
  if (c.win.size() != nperseg) {
    c.win = periodic_hann(nperseg);
    double acc = 0.0;
    for (double v : c.win) acc += v * v;
    c.win_sq = acc;
  }
  const double scale = 1.0 / (fs_hz * c.win_sq);  // 'density'

  const std::size_t nfreq = nfft / 2 + 1;
  out.f_hz.resize(nfreq);
  const double val = 1.0 / (static_cast<double>(nfft) * (1.0 / fs_hz));  // rfftfreq(nfft, 1/fs)
  for (std::size_t k = 0; k < nfreq; ++k) out.f_hz[k] = static_cast<double>(k) * val;
  out.pxx.assign(nfreq, 0.0);

  const bool use_pow2 = is_pow2(nfft);
  if (use_pow2 && (!c.pow2 || c.pow2->size() != nfft)) c.pow2 = std::make_unique<RealFftPow2>(nfft);
  // The power-of-two FFT reads only the nperseg windowed samples (the zero
  // padding is implicit); the mixed-radix one needs it explicitly.
  if (use_pow2) {
    c.seg.resize(nperseg);
  } else {
    c.kiss.SetFlag(Eigen::FFT<double>::HalfSpectrum);
    c.seg.assign(nfft, 0.0);
    c.spec.resize(nfreq);
  }
  c.power.resize(nfreq);
  double* seg = c.seg.data();
  double* pw = c.power.data();
  const double* win = c.win.data();
  double* pxx = out.pxx.data();
  const auto nf = static_cast<Eigen::Index>(nfft);
  for (std::size_t s = 0; s < nseg; ++s) {
    const double* xs = x.data() + s * step;
    double sum = 0.0;
    for (std::size_t i = 0; i < nperseg; ++i) sum += xs[i];
    const double mean = sum / static_cast<double>(nperseg);
    for (std::size_t i = 0; i < nperseg; ++i) seg[i] = win[i] * (xs[i] - mean);
    if (use_pow2) {
      c.pow2->power(seg, nperseg, pw);
    } else {
      if (nfft == 1) {
        c.spec[0] = {seg[0], 0.0};
      } else {
        c.kiss.fwd(c.spec.data(), seg, nf);
      }
      for (std::size_t k = 0; k < nfreq; ++k) pw[k] = c.spec[k].real() * c.spec[k].real() + c.spec[k].imag() * c.spec[k].imag();
    }
    // One-sided: fold the negative frequencies in, except DC and (even nfft)
    // the unpaired Nyquist bin.
    const std::size_t last_doubled = nfft % 2 == 0 ? nfreq - 1 : nfreq;
    pxx[0] += pw[0] * scale;
    for (std::size_t k = 1; k < last_doubled; ++k) pxx[k] += (pw[k] * scale) * 2.0;
    for (std::size_t k = std::max<std::size_t>(last_doubled, 1); k < nfreq; ++k) pxx[k] += pw[k] * scale;
  }
  if (nseg > 1)  // x / 1 == x exactly: one segment (the estimator's case) needs no pass
    for (double& p : out.pxx) p /= static_cast<double>(nseg);
}

Psd welch(std::span<const double> x, double fs_hz, const WelchOptions& opt) {
  Psd out;
  welch(x, fs_hz, opt, out);
  return out;
}

}  // namespace manip::dsp
