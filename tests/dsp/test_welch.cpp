#include <catch2/catch.hpp>

#include <stdexcept>

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
