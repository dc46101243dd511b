#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <stdexcept>

#include "dsp_test_util.hpp"
#include "manip/dsp/butterworth.hpp"
#include "manip/dsp/sosfilt.hpp"

using manip::dsp::BandType;
using manip::dsp::butter;
using manip::dsp::Sos;
using manip::dsp::test::Numbers;

namespace {

double coeff(const Sos& s, int i) {
  const double v[6] = {s.b0, s.b1, s.b2, s.a0, s.a1, s.a2};
  return v[i];
}

// |H(e^{j 2 pi f / fs})| of the cascade.
double magnitude(const std::vector<Sos>& sos, double f, double fs) {
  const std::complex<double> z1 = std::polar(1.0, -2.0 * std::numbers::pi * f / fs);  // z^-1
  std::complex<double> h{1.0, 0.0};
  for (const Sos& s : sos) h *= (s.b0 + s.b1 * z1 + s.b2 * z1 * z1) / (s.a0 + s.a1 * z1 + s.a2 * z1 * z1);
  return std::abs(h);
}

}  // namespace

TEST_CASE("butter: sections and sosfilt_zi match scipy, orders 1-8, low/high pass, five cut-offs") {
  // Every coefficient is compared relative to itself; structural zeros (b2, a2
  // of the first-order section of odd orders) must be exactly zero because
  // sosfiltfilt's default padlen counts them. zi solves (I - A^T) zi = B, whose matrix is nearly
  // singular for poles near z = 1 (1 Hz at 4 kHz: det ~ 2.5e-6 per section), so
  // scipy's own zi carries ~eps/det relative error: tolerance 1e-9.
  Numbers in("dsp/butter.txt");
  double worst_sos = 0.0, worst_zi = 0.0, worst_zero = 0.0;
  int cases = 0;
  while (!in.done()) {
    const int order = in.next_int();
    const double fc = in.next();
    const double fs = in.next();
    const BandType type = in.next_int() == 0 ? BandType::lowpass : BandType::highpass;
    const auto ns = static_cast<std::size_t>(in.next_int());
    const auto want = in.take(6 * ns);
    const auto want_zi = in.take(2 * ns);
    INFO("order " << order << " fc " << fc << " fs " << fs << (type == BandType::lowpass ? " low" : " high"));
    const auto sos = butter(order, fc, fs, type);
    REQUIRE(sos.size() == ns);
    for (std::size_t s = 0; s < ns; ++s) {
      const double* w6 = &want[6 * s];
      const double scale_b = std::max({std::fabs(w6[0]), std::fabs(w6[1]), std::fabs(w6[2])});
      for (int i = 0; i < 6; ++i) {
        const double w = w6[i];
        const double g = coeff(sos[s], i);
        const double scale = i < 3 ? scale_b : 1.0;  // a0 == 1
        if (i == 2 || i == 5) CHECK((g == 0.0) == (w == 0.0));  // decides padlen
        if (std::fabs(w) > 1e-10 * scale) {
          worst_sos = std::max(worst_sos, std::fabs(g - w) / std::fabs(w));
        } else {
          // Zero in exact arithmetic (a1 for poles on the imaginary axis at
          // fc = fs/4): both sides hold rounding noise. numpy on AVX-512
          // machines even uses SVML's tan, which returns tan(pi/4) = 1.0
          // where glibc returns the correctly rounded 1 - 2^-53.
          worst_zero = std::max(worst_zero, std::fabs(g - w) / scale);
        }
      }
    }
    const auto zi = manip::dsp::sosfilt_zi(sos);
    worst_zi = std::max(worst_zi, manip::dsp::test::rel_error(zi, want_zi, 1e-12));
    ++cases;
  }
  CHECK(cases == 80);
  CHECK(manip::dsp::test::observed("butter sections, max relative error", worst_sos) <= 1e-13);
  CHECK(manip::dsp::test::observed("butter exact-zero coefficients, max abs error", worst_zero) <= 1e-15);  // absolute, relative to the section's scale
  CHECK(manip::dsp::test::observed("sosfilt_zi, max relative error", worst_zi) <= 1e-9);
}

TEST_CASE("butter: the paper's high pass, order 5 at 1 Hz, 4 kHz (platform facts)") {
  const auto sos = butter(5, 1.0, 4000.0, BandType::highpass);
  REQUIRE(sos.size() == 3);
  const double want[3][6] = {{0.99746162, -0.99746162, 0, 1, -0.99843044, 0},
                             {1, -2, 1, 1, -1.99745916, 0.99746162},
                             {1, -2, 1, 1, -1.9990272, 0.99902967}};
  for (std::size_t s = 0; s < 3; ++s)
    for (int i = 0; i < 6; ++i) CHECK(coeff(sos[s], i) == Approx(want[s][i]).margin(6e-9));
  CHECK(sos[0].b2 == 0.0);
  CHECK(sos[0].a2 == 0.0);
  CHECK(manip::dsp::sosfiltfilt_padlen(sos) == 18);
  // Sections keep the response exact where [b, a] would not: the prewarped
  // cut-off is exactly -3 dB, and |H(0.5 Hz)| = 1/sqrt(1 + 2^10) = 0.0312.
  CHECK(magnitude(sos, 1.0, 4000.0) == Approx(1.0 / std::sqrt(2.0)).epsilon(1e-9));
  CHECK(magnitude(sos, 0.5, 4000.0) == Approx(1.0 / std::sqrt(1025.0)).epsilon(1e-6));
  CHECK(magnitude(sos, 1999.0, 4000.0) == Approx(1.0).epsilon(1e-9));
}

TEST_CASE("butter: -3 dB exactly at the cut-off and unit pass-band gain") {
  for (int order = 1; order <= 8; ++order) {
    for (double fc : {0.5, 1.0, 30.0, 400.0, 1500.0}) {
      const auto lp = butter(order, fc, 4000.0, BandType::lowpass);
      const auto hp = butter(order, fc, 4000.0, BandType::highpass);
      INFO("order " << order << " fc " << fc);
      CHECK(magnitude(lp, fc, 4000.0) == Approx(1.0 / std::sqrt(2.0)).epsilon(1e-9));
      CHECK(magnitude(hp, fc, 4000.0) == Approx(1.0 / std::sqrt(2.0)).epsilon(1e-9));
      CHECK(magnitude(lp, 0.0, 4000.0) == Approx(1.0).epsilon(1e-9));
      CHECK(magnitude(hp, 2000.0, 4000.0) == Approx(1.0).epsilon(1e-10));
      CHECK(lp.size() == static_cast<std::size_t>((order + 1) / 2));
    }
  }
}

TEST_CASE("butter: invalid designs throw std::invalid_argument") {
  CHECK_THROWS_AS(butter(0, 1.0, 4000.0, BandType::lowpass), std::invalid_argument);
  CHECK_THROWS_AS(butter(-2, 1.0, 4000.0, BandType::lowpass), std::invalid_argument);
  CHECK_THROWS_AS(butter(5, 0.0, 4000.0, BandType::highpass), std::invalid_argument);
  CHECK_THROWS_AS(butter(5, -1.0, 4000.0, BandType::highpass), std::invalid_argument);
  CHECK_THROWS_AS(butter(5, 2000.0, 4000.0, BandType::highpass), std::invalid_argument);
  CHECK_THROWS_AS(butter(5, 2500.0, 4000.0, BandType::lowpass), std::invalid_argument);
  CHECK_THROWS_AS(butter(5, 1.0, 0.0, BandType::lowpass), std::invalid_argument);
  CHECK_THROWS_AS(butter(5, 1.0, std::nan(""), BandType::lowpass), std::invalid_argument);
}
