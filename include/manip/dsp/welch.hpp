#pragma once
// Welch power spectral density with the defaults of scipy.signal.welch
// (scipy 1.10): periodic Hann window (get_window('hann', nperseg)), constant
// detrend per segment, 'density' scaling [unit^2/Hz], one-sided spectrum,
// 'mean' average over segments. The paper uses Welch PSD estimates of the
// unperturbed and perturbed jerk to choose the 1 Hz high-pass cut-off.
#include <span>
#include <vector>

namespace manip::dsp {

struct WelchOptions {
  int nperseg = 256;  // clamped to x.size() like scipy (which also warns)
  int noverlap = -1;  // -1: nperseg / 2 (after clamping)
  int nfft = -1;      // -1: nperseg; otherwise >= nperseg, segments zero padded
};

struct Psd {
  std::vector<double> f_hz;  // nfft / 2 + 1 bins, k * fs / nfft
  std::vector<double> pxx;
};

// Throws std::invalid_argument for fs_hz <= 0, nperseg < 1, noverlap >= nperseg
// (or < -1), nfft < nperseg. Empty x gives an empty Psd (as scipy).
// Allocates (result, one segment buffer, FFT plan cache per thread).
// FFT: built-in radix-4 for power-of-two nfft (fast: use these; zero padding
// beyond nperseg costs little, the transform is pruned), Eigen's kissfft
// (mixed radix, ~10x slower, O(n^2) for large prime factors) otherwise.
[[nodiscard]] Psd welch(std::span<const double> x, double fs_hz, const WelchOptions& opt = {});

// The same, into `out`, reusing its storage (a caller computing one PSD per
// trial avoids two nfft/2+1 allocations per call). Same values, bit for bit.
void welch(std::span<const double> x, double fs_hz, const WelchOptions& opt, Psd& out);

}  // namespace manip::dsp
