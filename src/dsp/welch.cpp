#include "manip/dsp/welch.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
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
  for (std::size_t i = 0; i < m; ++i) w[i] = 0.5 + 0.5 * std::cos(static_cast<double>(i) * step + (-pi));
  return w;
}

// Real FFT for power-of-two lengths: the n real samples are packed into n/2
// complex ones, transformed by an iterative radix-2 FFT and split into the
// n/2+1 bins of the one-sided spectrum. Twiddles come from cos/sin of each
// angle (no recurrences), so the error stays ~eps log2(n) of the signal norm.
// Eigen's kissfft needs 4.6 us for n = 256 on this machine (the FFT of every
// Welch segment), which made welch() slower than scipy's pocketfft. Real and
// imaginary parts live in separate arrays: with std::complex GCC 12 assembled
// the butterfly operands through the stack and stalled on store forwarding.
class RealFftPow2 {
 public:
  explicit RealFftPow2(std::size_t n)
      : n_(n), m_(n / 2), rev_(m_), twr_(m_), twi_(m_), spr_(m_), spi_(m_), re_(m_), im_(m_) {
    const double pi = std::numbers::pi;
    std::size_t bits = 0;
    while ((std::size_t{1} << bits) < m_) ++bits;
    for (std::size_t i = 0; i < m_; ++i) {
      std::size_t r = 0;
      for (std::size_t b = 0; b < bits; ++b) r |= ((i >> b) & 1U) << (bits - 1 - b);
      rev_[i] = r;
    }
    // Per-stage twiddles stored contiguously: the stage with butterflies of
    // span `half` uses twr_[half - 1 + j] = cos(-2 pi j / (2 half)), so its
    // inner loop is unit stride and vectorises.
    for (std::size_t half = 1; half < m_; half <<= 1) {
      for (std::size_t j = 0; j < half; ++j) {
        const double a = -pi * static_cast<double>(j) / static_cast<double>(half);
        twr_[half - 1 + j] = std::cos(a);
        twi_[half - 1 + j] = std::sin(a);
      }
    }
    for (std::size_t k = 0; k < m_; ++k) {
      const double a = -2.0 * pi * static_cast<double>(k) / static_cast<double>(n_);
      spr_[k] = std::cos(a);
      spi_[k] = std::sin(a);
    }
  }
  [[nodiscard]] std::size_t size() const { return n_; }

  // out_re/out_im: n/2 + 1 bins.
  void forward(const double* x, double* out_re, double* out_im) {
    double* re = re_.data();
    double* im = im_.data();
    for (std::size_t j = 0; j < m_; ++j) {
      re[rev_[j]] = x[2 * j];
      im[rev_[j]] = x[2 * j + 1];
    }
    for (std::size_t len = 2; len <= m_; len <<= 1) {
      const std::size_t half = len / 2;
      const double* __restrict wr = twr_.data() + (half - 1);
      const double* __restrict wi = twi_.data() + (half - 1);
      for (std::size_t i = 0; i < m_; i += len) {
        // Disjoint ranges: [i, i+half) and [i+half, i+len) of two arrays.
        double* __restrict ar = re + i;
        double* __restrict ai = im + i;
        double* __restrict br = re + i + half;
        double* __restrict bi = im + i + half;
        for (std::size_t j = 0; j < half; ++j) {
          const double vr = br[j] * wr[j] - bi[j] * wi[j];
          const double vi = br[j] * wi[j] + bi[j] * wr[j];
          br[j] = ar[j] - vr;
          bi[j] = ai[j] - vi;
          ar[j] += vr;
          ai[j] += vi;
        }
      }
    }
    // X[k] = E[k] + e^{-2 pi i k / n} O[k], E = (Z[k] + conj Z[m-k]) / 2,
    // O = (Z[k] - conj Z[m-k]) / (2i).
    out_re[0] = re[0] + im[0];
    out_im[0] = 0.0;
    out_re[m_] = re[0] - im[0];
    out_im[m_] = 0.0;
    for (std::size_t k = 1; k < m_; ++k) {
      const double zr = re[k], zi = im[k], cr = re[m_ - k], ci = -im[m_ - k];
      const double er = 0.5 * (zr + cr), ei = 0.5 * (zi + ci);
      const double o_r = 0.5 * (zi - ci), o_i = -0.5 * (zr - cr);
      out_re[k] = er + (spr_[k] * o_r - spi_[k] * o_i);
      out_im[k] = ei + (spr_[k] * o_i + spi_[k] * o_r);
    }
  }

 private:
  std::size_t n_, m_;
  std::vector<std::size_t> rev_;
  std::vector<double> twr_, twi_, spr_, spi_, re_, im_;
};

bool is_pow2(std::size_t n) { return n >= 2 && (n & (n - 1)) == 0; }

}  // namespace

Psd welch(std::span<const double> x, double fs_hz, const WelchOptions& opt) {
  if (!(fs_hz > 0.0) || !std::isfinite(fs_hz)) throw std::invalid_argument("welch: fs must be finite and > 0");
  if (opt.nperseg < 1) throw std::invalid_argument("welch: nperseg must be a positive integer");
  const std::size_t n = x.size();
  if (n == 0) return {};
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

  // Per-thread cache: window (one cos per sample, ~0.2 ms for a 12000-sample
  // segment) and its energy, FFT plans (the last power-of-two size; kissfft
  // keeps its own per-length cache) and the work buffers, whose fresh
  // allocation page-faulted on every call for long segments.
  struct Cache {
    std::vector<double> win;
    double win_sq = 0.0;
    std::unique_ptr<RealFftPow2> pow2;
    Eigen::FFT<double> kiss;
    std::vector<double> seg, spec_re, spec_im;
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
  Psd out;
  out.f_hz.resize(nfreq);
  const double val = 1.0 / (static_cast<double>(nfft) * (1.0 / fs_hz));  // rfftfreq(nfft, 1/fs)
  for (std::size_t k = 0; k < nfreq; ++k) out.f_hz[k] = static_cast<double>(k) * val;
  out.pxx.assign(nfreq, 0.0);

  const bool use_pow2 = is_pow2(nfft);
  if (use_pow2 && (!c.pow2 || c.pow2->size() != nfft)) c.pow2 = std::make_unique<RealFftPow2>(nfft);
  c.kiss.SetFlag(Eigen::FFT<double>::HalfSpectrum);
  c.seg.assign(nfft, 0.0);  // zero padding beyond nperseg stays zero
  c.spec.resize(nfreq);
  c.spec_re.resize(nfreq);
  c.spec_im.resize(nfreq);
  double* seg = c.seg.data();
  double* spec_re = c.spec_re.data();
  double* spec_im = c.spec_im.data();
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
      c.pow2->forward(seg, spec_re, spec_im);
    } else {
      if (nfft == 1) {
        c.spec[0] = {seg[0], 0.0};
      } else {
        c.kiss.fwd(c.spec.data(), seg, nf);
      }
      for (std::size_t k = 0; k < nfreq; ++k) spec_re[k] = c.spec[k].real(), spec_im[k] = c.spec[k].imag();
    }
    // One-sided: fold the negative frequencies in, except DC and (even nfft)
    // the unpaired Nyquist bin.
    const std::size_t last_doubled = nfft % 2 == 0 ? nfreq - 1 : nfreq;
    pxx[0] += (spec_re[0] * spec_re[0] + spec_im[0] * spec_im[0]) * scale;
    for (std::size_t k = 1; k < last_doubled; ++k)
      pxx[k] += ((spec_re[k] * spec_re[k] + spec_im[k] * spec_im[k]) * scale) * 2.0;
    for (std::size_t k = std::max<std::size_t>(last_doubled, 1); k < nfreq; ++k)
      pxx[k] += (spec_re[k] * spec_re[k] + spec_im[k] * spec_im[k]) * scale;
  }
  for (double& p : out.pxx) p /= static_cast<double>(nseg);
  return out;
}

}  // namespace manip::dsp
