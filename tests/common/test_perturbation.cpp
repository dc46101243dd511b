#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>

#include "manip/common/perturbation.hpp"

using manip::PerturbationProfile;

TEST_CASE("perturbation: zero at both ends, peak equals A_pert mid-pulse (eq. 22-23)") {
  PerturbationProfile p{0.15, 15.0};
  CHECK(p.normalized(0.0) == 0.0);
  CHECK(p.normalized(0.15) == 0.0);
  CHECK(p.normalized(-0.01) == 0.0);
  CHECK(p.normalized(0.2) == 0.0);
  CHECK(p.normalized(0.075) == Approx(1.0).epsilon(1e-12));
  CHECK(p.force_n(0.075, 0.0).x() == Approx(15.0));
  double mx = 0.0;
  for (int i = 0; i <= 15000; ++i) mx = std::max(mx, p.normalized(i * 1e-5));
  CHECK(mx == Approx(1.0).epsilon(1e-9));
}

TEST_CASE("perturbation: rate is the derivative of the force, continuous, zero at ends") {
  PerturbationProfile p{0.15, 15.0};
  CHECK(p.normalized_rate(0.0) == Approx(0.0).margin(1e-12));
  CHECK(p.normalized_rate(0.15) == Approx(0.0).margin(1e-12));
  const double h = 1e-7;
  for (double t = 0.001; t < 0.149; t += 0.0037) {
    const double fd = (p.normalized(t + h) - p.normalized(t - h)) / (2 * h);
    CHECK(fd == Approx(p.normalized_rate(t)).margin(1e-5));
  }
  // continuity of the rate at the section boundaries T/3, 2T/3
  for (double tb : {0.05, 0.10}) {
    CHECK(p.normalized_rate(tb - 1e-9) == Approx(p.normalized_rate(tb + 1e-9)).margin(1e-6));
  }
  // eq. 22 shape: rate at section-1 end equals +max, at section-2 end equals -max
  const double peak = 0.05 * (0.5 + 1.0 / std::numbers::pi);
  CHECK(p.normalized_rate(0.05) == Approx(1.0 / peak));
  CHECK(p.normalized_rate(0.10) == Approx(-1.0 / peak));
}

TEST_CASE("perturbation: direction follows phi counter-clockwise from +x1") {
  PerturbationProfile p{0.15, 15.0};
  const auto f = p.force_n(0.075, std::numbers::pi / 2.0);
  CHECK(f.x() == Approx(0.0).margin(1e-12));
  CHECK(f.y() == Approx(15.0));
}
