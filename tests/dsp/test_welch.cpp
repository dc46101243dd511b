#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "dsp_test_util.hpp"
#include "manip/dsp/welch.hpp"

using manip::dsp::welch;
using manip::dsp::WelchOptions;
using manip::dsp::test::Numbers;
using manip::dsp::test::rel_error;

namespace {

// Reads "nbins, then (bin, f, pxx) triples[, then the input signal]".
struct WelchRef {
  std::size_t nbins = 0;
  std::vector<std::size_t> bins;
  std::vector<double> f, pxx, input;
};

WelchRef read_ref(const std::string& file, std::size_t input_len) {
  Numbers in(file);
  WelchRef r;
  r.nbins = static_cast<std::size_t>(in.next());
  // Triples until the input (if any) starts; the last bin index is known.
  while (!in.done()) {
    const auto k = static_cast<std::size_t>(in.next());
    r.bins.push_back(k);
    r.f.push_back(in.next());
    r.pxx.push_back(in.next());
    if (input_len > 0 && k == r.nbins - 1) break;
  }
  if (input_len > 0) r.input = in.take(input_len);
  REQUIRE(in.done());
  return r;
}

void check(const manip::dsp::Psd& got, const WelchRef& want, const std::string& tag) {
  REQUIRE(got.f_hz.size() == want.nbins);
  REQUIRE(got.pxx.size() == want.nbins);
  std::vector<double> gf, gp;
  for (auto k : want.bins) {
    gf.push_back(got.f_hz[k]);
    gp.push_back(got.pxx[k]);
  }
  // Frequencies: same formula as rfftfreq, observed bit-identical.
  CHECK(rel_error(gf, want.f, 1e-12) <= 1e-15);
  // PSD: relative per bin down to 1e-9 of the peak. FFT rounding is ~eps
  // relative to the segment energy, so a bin 1e-9 below the peak can only be
  // trusted to ~1e-7 of itself in any FFT (scipy's pocketfft included); the
  // DC bin after constant detrending is pure rounding noise (~1e-30).
  CHECK(manip::dsp::test::observed(tag, rel_error(gp, want.pxx, 1e-9)) <= 1e-9);
}

}  // namespace

TEST_CASE("welch: trial jerk with scipy defaults (nperseg 256, 50% overlap)") {
  const auto x = manip::dsp::test::quantised_signal("dsp/trial_jerk.txt");
  const auto ref = read_ref("dsp/welch_trial_default.txt", 0);
  const auto psd = welch(x, 4000.0);
  check(psd, ref, "welch trial defaults");
  CHECK(psd.f_hz.size() == 129);
  CHECK(psd.f_hz[1] == Approx(4000.0 / 256.0));
}

TEST_CASE("welch: whole signal as one segment, zero padded to nfft = 16384") {
  const auto x = manip::dsp::test::quantised_signal("dsp/trial_jerk.txt");
  const auto ref = read_ref("dsp/welch_trial_whole.txt", 0);
  WelchOptions opt;
  opt.nperseg = 12000;
  opt.nfft = 16384;
  check(welch(x, 4000.0, opt), ref, "welch trial nperseg=12000 nfft=16384");
}

TEST_CASE("welch: the estimator's shape, a trial zero padded to nfft = 65536 (pruned transform)") {
  const auto x = manip::dsp::test::quantised_signal("dsp/trial_jerk.txt");
  const auto ref = read_ref("dsp/welch_trial_nfft65536.txt", 0);
  WelchOptions opt;
  opt.nperseg = 12000;
  opt.nfft = 65536;
  check(welch(x, 4000.0, opt), ref, "welch trial nperseg=12000 nfft=65536");
  // The reusing overload gives the same numbers, also when `out` held another size.
  manip::dsp::Psd out = welch(x, 4000.0);
  welch(x, 4000.0, opt, out);
  const auto fresh = welch(x, 4000.0, opt);
  CHECK(out.pxx == fresh.pxx);
  CHECK(out.f_hz == fresh.f_hz);
}

TEST_CASE("welch: odd segment length, zero padded (half-empty last FFT input)") {
  const auto x = manip::dsp::test::quantised_signal("dsp/trial_jerk.txt");
  const auto ref = read_ref("dsp/welch_trial_odd_nfft16384.txt", 0);
  const std::vector<double> head(x.begin(), x.begin() + 3001);
  WelchOptions opt;
  opt.nperseg = 3001;
  opt.nfft = 16384;
  check(welch(head, 4000.0, opt), ref, "welch nperseg=3001 nfft=16384");
}

TEST_CASE("welch: power-of-two FFT against a direct DFT for every small size and padding") {
  // Covers the radix-4 / radix-2 stage mixes and every pruning factor P.
  for (int nfft = 2; nfft <= 256; nfft *= 2) {
    for (int len = 1; len <= nfft; len += (len < 8 ? 1 : 7)) {
      std::vector<double> x(static_cast<std::size_t>(len));
      for (int i = 0; i < len; ++i) x[static_cast<std::size_t>(i)] = std::sin(0.37 * i * i + 1.0) + 0.1 * i;
      WelchOptions opt;
      opt.nperseg = len;
      opt.nfft = nfft;
      opt.noverlap = len / 2;
      if (len == 1) opt.noverlap = 0;
      const auto got = welch(x, 1.0, opt);
      // Reference: detrend, periodic Hann, direct DFT in long double, density scaling.
      const double pi = 3.141592653589793238462643383279502884;
      long double mean = 0;
      for (double v : x) mean += v;
      mean /= len;
      std::vector<long double> seg(static_cast<std::size_t>(len));
      long double wsum = 0;
      for (int i = 0; i < len; ++i) {
        const long double w = len == 1 ? 1.0L : 0.5L - 0.5L * std::cos(2.0L * pi * i / len);
        seg[static_cast<std::size_t>(i)] = w * (x[static_cast<std::size_t>(i)] - mean);
        wsum += w * w;
      }
      double peak = 0;
      std::vector<double> want(static_cast<std::size_t>(nfft / 2 + 1));
      for (int k = 0; k <= nfft / 2; ++k) {
        long double re = 0, im = 0;
        for (int i = 0; i < len; ++i) {
          const long double a = -2.0L * pi * static_cast<long double>((static_cast<long long>(i) * k) % nfft) / nfft;
          re += seg[static_cast<std::size_t>(i)] * std::cos(a);
          im += seg[static_cast<std::size_t>(i)] * std::sin(a);
        }
        long double p = (re * re + im * im) / wsum;
        if (k > 0 && k < nfft / 2) p *= 2;
        want[static_cast<std::size_t>(k)] = static_cast<double>(p);
        peak = std::max(peak, want[static_cast<std::size_t>(k)]);
      }
      REQUIRE(got.pxx.size() == want.size());
      double err = 0;
      for (std::size_t k = 0; k < want.size(); ++k) err = std::max(err, std::abs(got.pxx[k] - want[k]));
      INFO("nfft " << nfft << " len " << len);
      CHECK(err <= 1e-13 * std::max(peak, 1e-300));
    }
  }
}

TEST_CASE("welch: odd nfft with explicit overlap, nperseg clamped to a short input") {
  {
    const auto ref = read_ref("dsp/welch_short_oddnfft.txt", 1000);
    WelchOptions opt;
    opt.nperseg = 100;
    opt.noverlap = 30;
    opt.nfft = 105;
    check(welch(ref.input, 250.0, opt), ref, "welch odd nfft 105, noverlap 30");
  }
  {
    const auto ref = read_ref("dsp/welch_short_clamped.txt", 200);
    check(welch(ref.input, 100.0), ref, "welch nperseg clamped to 200");
  }
}

TEST_CASE("welch: white noise integrates to its variance (density scaling)") {
  const auto x = manip::dsp::test::quantised_signal("dsp/trial_jerk.txt");
  // Check Parseval on a detrended, stationary chunk: the last second is pure
  // noise (sigma 0.5 m/s^3) once the reach has ended.
  std::vector<double> tail(x.end() - 3000, x.end());
  const auto psd = welch(tail, 4000.0);
  double area = 0.0;
  for (std::size_t k = 0; k < psd.pxx.size(); ++k) area += psd.pxx[k] * (psd.f_hz[1] - psd.f_hz[0]);
  CHECK(area == Approx(0.25).epsilon(0.1));
}

TEST_CASE("welch: argument errors") {
  std::vector<double> x(1000, 1.0);
  CHECK_THROWS_AS(welch(x, 0.0), std::invalid_argument);
  CHECK_THROWS_AS(welch(x, 100.0, WelchOptions{0, -1, -1}), std::invalid_argument);
  CHECK_THROWS_AS(welch(x, 100.0, WelchOptions{256, 256, -1}), std::invalid_argument);
  CHECK_THROWS_AS(welch(x, 100.0, WelchOptions{256, -2, -1}), std::invalid_argument);
  CHECK_THROWS_AS(welch(x, 100.0, WelchOptions{256, -1, 255}), std::invalid_argument);
  CHECK(welch(std::vector<double>{}, 100.0).pxx.empty());
}
