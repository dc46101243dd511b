#pragma once
// Savitzky-Golay smoothing and differentiation with the semantics of
// scipy.signal.savgol_coeffs / savgol_filter(mode='interp') (scipy 1.10).
//
// The paper filters all measured and simulated signals with "a fifth order
// Savitzky-Golay filter with a cut-off frequency of 30 Hz" at fs = 4 kHz and
// takes velocity, acceleration and jerk as derivatives of the same local fits.
//
// Semantics: sample i of the output is the deriv-th derivative, at the
// window centre, of the least-squares polynomial of degree polyorder through
// x[i - window/2 .. i + window/2] (sample spacing delta). Within window/2
// samples of either end (mode='interp') the output instead comes from ONE
// polynomial fitted to the first (last) `window` samples, evaluated at each
// edge sample.
//
// Accuracy note: scipy computes the coefficients with lstsq on the unscaled
// Vandermonde matrix of -h..h, whose condition number is ~1e11 for window 225,
// order 5; its coefficients are only good to ~4e-8 (normwise relative) and its
// filtered derivatives of a reach trajectory to ~3e-6. We solve the same
// least-squares problem in the scaled variable u = x / h with a Householder
// QR: coefficients agree with the exact rational solution to ~5e-15, filtered
// outputs to within a few eps * (condition number of the data), see
// tests/dsp/test_savgol.cpp. Results therefore match scipy only to scipy's own
// error.
//
// Odd windows only (the platform convention; scipy would accept even ones).
#include <span>
#include <vector>

namespace manip::dsp {

// scipy.signal.savgol_coeffs(window, polyorder, deriv, delta), i.e. pos = centre,
// use='conv' order: coefficient j multiplies x[i + window/2 - j]. Coefficients
// are exactly symmetric (even deriv) or antisymmetric (odd deriv). deriv >
// polyorder gives all zeros, as in scipy. Throws std::invalid_argument for an
// even or non-positive window, polyorder < 0, polyorder >= window, deriv < 0,
// delta not finite and > 0.
[[nodiscard]] std::vector<double> savgol_coeffs(int window, int polyorder, int deriv = 0,
                                                double delta = 1.0);

class SavgolFilter {
 public:
  // Precomputes the convolution taps and the edge-fit operators; throws
  // std::invalid_argument as savgol_coeffs does.
  SavgolFilter(int window, int polyorder, int deriv, double delta);

  [[nodiscard]] int window() const { return window_; }
  [[nodiscard]] int polyorder() const { return polyorder_; }
  [[nodiscard]] int deriv() const { return deriv_; }
  [[nodiscard]] double delta() const { return delta_; }
  // Same values as savgol_coeffs(window, polyorder, deriv, delta).
  [[nodiscard]] std::vector<double> coeffs() const;

  // y = savgol_filter(x, window, polyorder, deriv, delta, mode='interp').
  // Throws std::invalid_argument if x.size() < window, y.size() != x.size(), or
  // x and y overlap (the convolution reads x around samples already written).
  // Never allocates; safe to call concurrently on one filter.
  void apply(std::span<const double> x, std::span<double> y) const;

 private:
  int window_;
  int polyorder_;
  int deriv_;
  double delta_;
  int half_;
  bool zero_;  // deriv > polyorder: output identically 0 (scipy semantics)
  // Interior taps in "dot" order, w[k] multiplies x[i + k] (and, with sign
  // (-1)^deriv, x[i - k]); k = 0..half_.
  std::vector<double> taps_;
  // Least-squares fit operator (polyorder+1) x window, row-major: coefficients
  // of the fitted polynomial in u = (t - half) / half, t = 0..window-1.
  std::vector<double> fit_;
  // Derivative-evaluation operators, half_ x (polyorder+1) row-major: value of
  // d^deriv/dt^deriv of u^k, divided by delta^deriv, at t = 0..half-1 (left)
  // and t = window-half..window-1 (right).
  std::vector<double> eval_left_;
  std::vector<double> eval_right_;
};

// -3 dB (half-power, |H| = 1/sqrt(2)) frequency of the order-`polyorder`
// Savitzky-Golay smoother (deriv 0) with this window at fs_hz: the first
// crossing of 1/sqrt(2) going up from 0 Hz. +infinity if |H| stays above
// 1/sqrt(2) up to fs/2 (e.g. window == polyorder + 1, an interpolating fit).
// Platform facts, order 5 at 4 kHz: 221 -> 30.6 Hz, 225 -> 30.1 Hz, 229 -> 29.6 Hz.
[[nodiscard]] double savgol_cutoff_hz(int window, int polyorder, double fs_hz);

// Odd window (> polyorder) whose savgol_cutoff_hz is NEAREST to fc_hz.
// Note: "smallest odd window whose -3 dB point is <= fc" would give 227 for the
// paper's setting (225 has its -3 dB point at 30.09 Hz, 227 at 29.83 Hz); the
// platform facts and the estimator expect 225 for (4 kHz, 30 Hz, order 5),
// which is the nearest. The -3 dB point decreases monotonically with the window,
// so this is a bracketing search, O(log window) coefficient designs (~1 ms).
// Throws std::invalid_argument unless fs_hz > 0, 0 < fc_hz < fs_hz / 2,
// polyorder >= 0, and the window needed stays below 2^18 samples.
[[nodiscard]] int savgol_window_for_cutoff(double fs_hz, double fc_hz, int polyorder);

namespace detail {
// SavgolFilter::apply uses an AVX2+FMA kernel when the CPU has it (x86-64,
// GCC/Clang) and a portable SSE2/vector-extension kernel otherwise; the two
// differ at the last-ulp level (FMA rounds once). For tests and for runs that
// must be bit-reproducible across machines: allow=false forces the portable
// kernel process-wide.
void savgol_allow_avx2(bool allow);
[[nodiscard]] bool savgol_uses_avx2();
}  // namespace detail

}  // namespace manip::dsp
