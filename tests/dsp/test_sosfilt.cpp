#include <catch2/catch.hpp>

#include <stdexcept>
#include <string>

#include "dsp_test_util.hpp"
#include "manip/dsp/butterworth.hpp"
#include "manip/dsp/sosfilt.hpp"

using manip::dsp::BandType;
using manip::dsp::butter;
using manip::dsp::Sos;
using manip::dsp::sosfilt;
using manip::dsp::sosfiltfilt;
using manip::dsp::test::Numbers;
using manip::dsp::test::observed;
using manip::dsp::test::rel_error;

namespace {

const std::vector<double>& trial_jerk() {
  static const std::vector<double> x = manip::dsp::test::quantised_signal("dsp/trial_jerk.txt");
  return x;
}

// Reads "index value" pairs (after `skip` leading numbers) and compares.
double compare_pairs(const std::string& file, const std::vector<double>& got, std::vector<double>* leading = nullptr,
                     std::size_t skip = 0) {
  Numbers in(file);
  if (leading) *leading = in.take(skip);
  std::vector<double> g, w;
  while (!in.done()) {
    const auto i = static_cast<std::size_t>(in.next());
    w.push_back(in.next());
    g.push_back(got.at(i));
  }
  REQUIRE(w.size() > 800);
  return rel_error(g, w);
}

}  // namespace

// Tolerance for filtered signals: relative per sample, with values below 1e-3
// of the signal's peak compared at 1e-3 * peak (rel_error): zero crossings of a
// high-passed jerk carry no relative accuracy. Filtering is well conditioned
// in sections; observed errors are ~1e-13, the bound is the brief's 1e-9.
constexpr double kTol = 1e-9;

TEST_CASE("sosfilt: 3 s trial at 4 kHz through the paper's high pass, zero state and sosfilt_zi state") {
  const auto& x = trial_jerk();
  REQUIRE(x.size() == 12000);
  const auto hp = butter(5, 1.0, 4000.0, BandType::highpass);
  std::vector<double> y(x.size());
  sosfilt(hp, x, y);
  CHECK(observed("sosfilt trial hp5, zero state", compare_pairs("dsp/sosfilt_trial_hp5_1hz.txt", y)) <= kTol);

  auto zi = manip::dsp::sosfilt_zi(hp);
  for (double& v : zi) v *= x[0];
  sosfilt(hp, x, y, zi);
  std::vector<double> zf_want;
  CHECK(observed("sosfilt trial hp5, zi state", compare_pairs("dsp/sosfilt_trial_hp5_zi.txt", y, &zf_want, 6)) <= kTol);
  CHECK(observed("sosfilt trial hp5, final state zf", rel_error(zi, zf_want)) <= kTol);
}

TEST_CASE("sosfilt: bit-identical to scipy given scipy's own sections") {
  // Our butter() and scipy's differ in the last ulp of the gain (numpy uses
  // SVML transcendentals on AVX-512 machines); fed scipy's exact sections,
  // sosfilt performs scipy's operations in scipy's order.
  Numbers in("dsp/butter.txt");
  std::vector<Sos> scipy_hp5;
  while (!in.done() && scipy_hp5.empty()) {
    const int order = in.next_int();
    const double fc = in.next(), fs = in.next();
    const int type = in.next_int();
    const auto ns = static_cast<std::size_t>(in.next_int());
    const auto v = in.take(8 * ns);
    if (order == 5 && fc == 1.0 && fs == 4000.0 && type == 1)
      for (std::size_t s = 0; s < ns; ++s)
        scipy_hp5.push_back({v[6 * s], v[6 * s + 1], v[6 * s + 2], v[6 * s + 3], v[6 * s + 4], v[6 * s + 5]});
  }
  REQUIRE(scipy_hp5.size() == 3);
  const auto& x = trial_jerk();
  std::vector<double> y(x.size());
  sosfilt(scipy_hp5, x, y);
  CHECK(observed("sosfilt trial hp5 with scipy's sections (bit-identical)",
                 compare_pairs("dsp/sosfilt_trial_hp5_1hz.txt", y)) == 0.0);
  // sosfiltfilt additionally depends on sosfilt_zi (our 2x2 LU vs LAPACK).
  sosfiltfilt(scipy_hp5, x, y);
  CHECK(observed("sosfiltfilt trial hp5 with scipy's sections", compare_pairs("dsp/sosfiltfilt_trial_hp5_1hz.txt", y)) <=
        kTol);
}

TEST_CASE("sosfiltfilt: 3 s trial at 4 kHz, paper's 1 Hz high pass and a 30 Hz low pass") {
  const auto& x = trial_jerk();
  std::vector<double> y(x.size());
  sosfiltfilt(butter(5, 1.0, 4000.0, BandType::highpass), x, y);
  CHECK(observed("sosfiltfilt trial hp5 1 Hz", compare_pairs("dsp/sosfiltfilt_trial_hp5_1hz.txt", y)) <= kTol);
  sosfiltfilt(butter(4, 30.0, 4000.0, BandType::lowpass), x, y);
  CHECK(observed("sosfiltfilt trial lp4 30 Hz", compare_pairs("dsp/sosfiltfilt_trial_lp4_30hz.txt", y)) <= kTol);
}

TEST_CASE("sosfiltfilt: signals just longer than padlen, and the error at len <= padlen") {
  Numbers in("dsp/sosfiltfilt_short.txt");
  int cases = 0;
  double worst = 0.0;
  while (!in.done()) {
    const int order = in.next_int();
    const double fc = in.next();
    const double fs = in.next();
    const BandType type = in.next_int() == 0 ? BandType::lowpass : BandType::highpass;
    const auto n = static_cast<std::size_t>(in.next_int());
    const int padlen = in.next_int();
    const auto x = in.take(n);
    const auto want = in.take(n);
    const auto sos = butter(order, fc, fs, type);
    INFO("order " << order << " n " << n);
    CHECK(manip::dsp::sosfiltfilt_padlen(sos) == padlen);
    std::vector<double> y(n);
    sosfiltfilt(sos, x, y);
    worst = std::max(worst, rel_error(y, want));

    // Exactly padlen samples: scipy raises; so do we, naming both lengths.
    const std::span<const double> too_short(x.data(), static_cast<std::size_t>(padlen));
    std::vector<double> y2(too_short.size());
    try {
      sosfiltfilt(sos, too_short, y2);
      FAIL("no exception for len == padlen");
    } catch (const std::invalid_argument& e) {
      const std::string msg = e.what();
      CHECK(msg.find(std::to_string(padlen)) != std::string::npos);
      CHECK(msg.find("padlen") != std::string::npos);
    }
    ++cases;
  }
  CHECK(cases == 8);
  CHECK(observed("sosfiltfilt short signals (8 cases)", worst) <= kTol);
}

TEST_CASE("sosfiltfilt_padlen follows scipy's count of first-order sections") {
  CHECK(manip::dsp::sosfiltfilt_padlen(butter(5, 1.0, 4000.0, BandType::highpass)) == 18);
  CHECK(manip::dsp::sosfiltfilt_padlen(butter(4, 1.0, 4000.0, BandType::highpass)) == 15);
  CHECK(manip::dsp::sosfiltfilt_padlen(butter(1, 1.0, 4000.0, BandType::lowpass)) == 6);
  CHECK(manip::dsp::sosfiltfilt_padlen(butter(2, 1.0, 4000.0, BandType::lowpass)) == 9);
  // min(#b2 == 0, #a2 == 0), not "sections with both": a section with only
  // b2 == 0 does not shorten the padding.
  const std::vector<Sos> mixed{{1, 0.5, 0, 1, -0.5, 0.1}, {1, 0.2, 0.1, 1, 0.1, 0}};
  CHECK(manip::dsp::sosfiltfilt_padlen(mixed) == 3 * (2 * 2 + 1 - 1));
  const std::vector<Sos> no_first_order{{1, 0.5, 0, 1, -0.5, 0.1}};
  CHECK(manip::dsp::sosfiltfilt_padlen(no_first_order) == 3 * (2 * 1 + 1 - 0));
}

TEST_CASE("sosfilt/sosfiltfilt: in place equals out of place, argument errors") {
  const auto& x = trial_jerk();
  const auto hp = butter(5, 1.0, 4000.0, BandType::highpass);
  std::vector<double> y(x.size()), inplace = x;
  sosfiltfilt(hp, x, y);
  sosfiltfilt(hp, inplace, inplace);
  CHECK(inplace == y);
  inplace = x;
  sosfilt(hp, x, y);
  sosfilt(hp, inplace, inplace);
  CHECK(inplace == y);

  std::vector<double> shorter(x.size() - 1);
  CHECK_THROWS_AS(sosfilt(hp, x, shorter), std::invalid_argument);
  CHECK_THROWS_AS(sosfiltfilt(hp, x, shorter), std::invalid_argument);
  std::vector<double> zi(5);
  CHECK_THROWS_AS(sosfilt(hp, x, y, zi), std::invalid_argument);
  CHECK_THROWS_AS(sosfilt({}, x, y), std::invalid_argument);
  std::vector<Sos> unnormalised = hp;
  unnormalised[1].a0 = 2.0;
  CHECK_THROWS_AS(sosfilt(unnormalised, x, y), std::invalid_argument);
  CHECK_THROWS_AS(sosfiltfilt(unnormalised, x, y), std::invalid_argument);
  const std::vector<Sos> integrator{{1, 0, 0, 1, -1, 0}};  // pole at z = 1
  CHECK_THROWS_AS(manip::dsp::sosfilt_zi(integrator), std::invalid_argument);
  std::vector<double> overlap = x;
  CHECK_THROWS_AS(sosfilt(hp, std::span<const double>(overlap.data(), 100), std::span<double>(overlap.data() + 1, 100)),
                  std::invalid_argument);
}

TEST_CASE("sosfilt: cascades longer than the register-resident kernels") {
  // 8 and 40 sections (generic state-in-memory path and the zero-state block
  // path) must equal applying the halves one after the other, bit for bit.
  const auto& x = trial_jerk();
  auto a = butter(8, 100.0, 4000.0, BandType::lowpass);
  const auto b = butter(8, 5.0, 4000.0, BandType::highpass);
  std::vector<Sos> ab = a;
  ab.insert(ab.end(), b.begin(), b.end());
  std::vector<double> y1(x.size()), y2(x.size());
  sosfilt(a, x, y1);
  sosfilt(b, y1, y1);
  sosfilt(ab, x, y2);
  CHECK(y1 == y2);

  std::vector<Sos> many;
  for (int i = 0; i < 10; ++i) many.insert(many.end(), ab.begin(), ab.begin() + 4);  // 40 sections
  std::vector<double> z1(x.size()), z2(x.size());
  z1 = x;
  for (int i = 0; i < 10; ++i) sosfilt(std::span<const Sos>(ab.data(), 4), z1, z1);
  sosfilt(many, x, z2);
  CHECK(z1 == z2);
}

TEST_CASE("sosfilt_zi: steady state for a constant input") {
  for (int order : {1, 2, 5, 6}) {
    const auto lp = butter(order, 30.0, 4000.0, BandType::lowpass);
    auto zi = manip::dsp::sosfilt_zi(lp);
    for (double& v : zi) v *= 3.5;
    std::vector<double> x(500, 3.5), y(500);
    sosfilt(lp, x, y, zi);
    for (double v : y) CHECK(v == Approx(3.5).epsilon(1e-9));
  }
}
