#include "manip/dsp/welch.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
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

  const std::vector<double> win = periodic_hann(nperseg);
  double win_sq = 0.0;
  for (double v : win) win_sq += v * v;
  const double scale = 1.0 / (fs_hz * win_sq);  // 'density'

  const std::size_t nfreq = nfft / 2 + 1;
  Psd out;
  out.f_hz.resize(nfreq);
  const double val = 1.0 / (static_cast<double>(nfft) * (1.0 / fs_hz));  // rfftfreq(nfft, 1/fs)
  for (std::size_t k = 0; k < nfreq; ++k) out.f_hz[k] = static_cast<double>(k) * val;
  out.pxx.assign(nfreq, 0.0);

  // One FFT object per thread: kissfft caches its twiddles/plans per length.
  thread_local Eigen::FFT<double> fft;
  fft.SetFlag(Eigen::FFT<double>::HalfSpectrum);
  std::vector<double> seg(nfft, 0.0);
  std::vector<std::complex<double>> spec(nfreq);
  const auto nf = static_cast<Eigen::Index>(nfft);
  for (std::size_t s = 0; s < nseg; ++s) {
    const double* xs = x.data() + s * step;
    double sum = 0.0;
    for (std::size_t i = 0; i < nperseg; ++i) sum += xs[i];
    const double mean = sum / static_cast<double>(nperseg);
    for (std::size_t i = 0; i < nperseg; ++i) seg[i] = win[i] * (xs[i] - mean);
    fft.fwd(spec.data(), seg.data(), nf);
    for (std::size_t k = 0; k < nfreq; ++k) {
      double p = (spec[k].real() * spec[k].real() + spec[k].imag() * spec[k].imag()) * scale;
      // One-sided: fold the negative frequencies in, except DC and (even
      // nfft) the unpaired Nyquist bin.
      if (k > 0 && !(nfft % 2 == 0 && k == nfreq - 1)) p *= 2.0;
      out.pxx[k] += p;
    }
  }
  for (double& p : out.pxx) p /= static_cast<double>(nseg);
  return out;
}

}  // namespace manip::dsp
