// Distribution functions and tests against scipy/numpy (fixture script:
// tests/fixtures/diagnosis/make_fixtures.py), and Holm's procedure against
// a hand-worked example.
#include <catch2/catch.hpp>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "fixtures.hpp"
#include "manip/diagnosis/stats.hpp"

using namespace manip::diagnosis;

TEST_CASE("t, chi-square and normal tails match scipy.stats", "[diagnosis][stats]") {
  std::ifstream in(manip::testutil::fixture_path("diagnosis/stats.txt"));
  REQUIRE(in);
  std::string line;
  int checked = 0;
  const auto series = manip::testutil::read_numbers("diagnosis/ar1_series.txt");
  REQUIRE(series.size() == 500);
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream is(line);
    std::string name;
    double a = 0, b = 0, v = 0;
    is >> name >> a >> b >> v;
    INFO(line);
    if (name == "t_sf") CHECK(stats::t_sf(b, a) == Approx(v).epsilon(1e-10).margin(1e-300));
    if (name == "t_isf") CHECK(stats::t_isf(b, a) == Approx(v).epsilon(1e-8));
    if (name == "chi2_sf") CHECK(stats::chi2_sf(b, a) == Approx(v).epsilon(1e-9).margin(1e-300));
    if (name == "norm_isf") CHECK(stats::norm_isf(b) == Approx(v).epsilon(1e-10).margin(1e-12));
    if (name == "ljung_box_q") CHECK(stats::ljung_box(series, static_cast<int>(a)).q == Approx(v).epsilon(1e-10));
    if (name == "ljung_box_p") CHECK(stats::ljung_box(series, static_cast<int>(a)).p_value == Approx(v).epsilon(1e-8).margin(1e-300));
    if (name == "skew") CHECK(stats::skewness(series) == Approx(v).epsilon(1e-10));
    if (name == "kurt") CHECK(stats::excess_kurtosis(series) == Approx(v).epsilon(1e-10));
    if (name == "pct25") CHECK(stats::percentile(series, 2.5) == Approx(v).epsilon(1e-12));
    if (name == "pct975") CHECK(stats::percentile(series, 97.5) == Approx(v).epsilon(1e-12));
    ++checked;
  }
  CHECK(checked == 101);
}

TEST_CASE("Holm step-down adjustment", "[diagnosis][stats]") {
  // m = 4, sorted p 0.01, 0.02, 0.03, 0.5 -> 0.04, max(0.04, 0.06), max(0.06, 0.06), max(0.06, 0.5)
  const std::vector<double> p = {0.03, 0.5, 0.01, 0.02};
  const auto a = stats::holm_adjust(p);
  CHECK(a[0] == Approx(0.06));
  CHECK(a[1] == Approx(0.5));
  CHECK(a[2] == Approx(0.04));
  CHECK(a[3] == Approx(0.06));
}

TEST_CASE("one-sided t test of fold gains", "[diagnosis][stats]") {
  // gains 1..5: mean 3, sd sqrt(2.5), se sqrt(0.5), t = 3 / sqrt(0.5)
  const std::vector<double> g = {1, 2, 3, 4, 5};
  const auto t = stats::one_sided_t(g);
  CHECK(t.mean == Approx(3.0));
  CHECK(t.se == Approx(std::sqrt(0.5)));
  CHECK(t.t == Approx(3.0 / std::sqrt(0.5)));
  CHECK(t.p_value == Approx(stats::t_sf(3.0 / std::sqrt(0.5), 4.0)));
  CHECK(t.p_value < 0.01);
}

TEST_CASE("profile-likelihood interval of a parabolic profile", "[diagnosis][stats]") {
  // NLL(a) = 100 + 40 (a - 0.7)^2: 2 (NLL - min) <= chi2_1(0.95) = 3.841458820694124
  // (scipy.stats.chi2.ppf(0.95, 1)) gives a = 0.7 +- sqrt(3.8414588 / 80).
  const double half = std::sqrt(3.841458820694124 / 80.0);
  auto nll = [](double a) { return 100.0 + 40.0 * (a - 0.7) * (a - 0.7); };
  SECTION("the profile's points, unevenly spaced, in the order profile() evaluates them") {
    const std::vector<double> a = {0.0, 1.0, 2.0, 0.68, 0.71};
    std::vector<double> y;
    for (const double x : a) y.push_back(nll(x));
    const auto pi = stats::profile_interval(a, y);
    CHECK(pi.center == Approx(0.7).epsilon(1e-10));
    CHECK(pi.half_width == Approx(half).epsilon(1e-10));
  }
  SECTION("a 99 % level widens it by z_0.995 / z_0.975") {
    const std::vector<double> a = {0.2, 0.9, 1.3};
    std::vector<double> y;
    for (const double x : a) y.push_back(nll(x));
    const auto pi = stats::profile_interval(a, y, 0.99);
    CHECK(pi.half_width == Approx(half * 2.5758293035489004 / 1.959963984540054).epsilon(1e-9));
  }
  SECTION("the least-squares parabola through points off a parabola (hand-solved normal equations)") {
    // x = -1, 0, 1, 2; y = 3, 1, 0, 4: y = c0 + c1 x + c2 x^2 by least squares
    // gives c2 = 1.5, c1 = -1.3, c0 = 0.4 (normal equations by hand from the
    // sums x 2, x^2 6, x^3 8, x^4 18, y 8, xy 5, x^2 y 19; numpy.polyfit
    // agrees): vertex 1.3 / 3, half-width sqrt(3.8414588 / 3).
    const std::vector<double> a = {-1, 0, 1, 2}, y = {3, 1, 0, 4};
    const auto pi = stats::profile_interval(a, y);
    CHECK(pi.center == Approx(1.3 / 3.0).epsilon(1e-10));
    CHECK(pi.half_width == Approx(std::sqrt(3.841458820694124 / 3.0)).epsilon(1e-9));
  }
  SECTION("not convex, or too few distinct points: no interval") {
    const std::vector<double> a = {0.0, 1.0, 2.0}, concave = {0.0, 1.0, 0.0};
    CHECK(std::isnan(stats::profile_interval(a, concave).half_width));
    const std::vector<double> a2 = {0.0, 1.0, 1.0}, y2 = {1.0, 0.0, 0.0};
    CHECK(std::isnan(stats::profile_interval(a2, y2).half_width));
    const std::vector<double> one = {0.5}, y1 = {1.0};
    CHECK(std::isnan(stats::profile_interval(one, y1).half_width));
  }
}

TEST_CASE("stats: signed_root_interval of a profile sampled far apart") {
  // NLL(x) = 100 + 40 (x - 0.7)^2: {x : 2 (NLL - min) <= chi2_1(0.95)} is
  // 0.7 +- sqrt(3.841458820694124 / 80) (scipy.stats.chi2.ppf(0.95, 1)); the
  // signed root is linear in x, so interpolating it between points 0.5 and
  // 0.7 apart is exact.
  const double half = std::sqrt(3.841458820694124 / 80.0);
  auto nll = [](double x) { return 100.0 + 40.0 * (x - 0.7) * (x - 0.7); };
  SECTION("points on both sides, unsorted, one profiled twice") {
    const std::vector<double> x = {1.5, 0.0, 0.8, 0.5, 0.8};
    std::vector<double> y;
    for (const double v : x) y.push_back(nll(v));
    y[4] += 0.3;  // the same point profiled again, worse: the better one counts
    const auto ri = stats::signed_root_interval(x, y);
    REQUIRE(ri.valid);
    CHECK(ri.lo == Approx(0.7 - half).epsilon(1e-12));
    CHECK(ri.hi == Approx(0.7 + half).epsilon(1e-12));
    CHECK_FALSE(ri.lo_open);
    CHECK_FALSE(ri.hi_open);
    const auto r99 = stats::signed_root_interval(x, y, 0.99);
    CHECK(r99.hi - 0.7 == Approx(half * 2.5758293035489004 / 1.959963984540054).epsilon(1e-9));
  }
  SECTION("no point far enough on one side: that end open at the outermost point") {
    const std::vector<double> x = {0.0, 0.5, 0.7, 0.8};
    std::vector<double> y;
    for (const double v : x) y.push_back(nll(v));
    const auto ri = stats::signed_root_interval(x, y);
    REQUIRE(ri.valid);
    CHECK(ri.lo == Approx(0.7 - half).epsilon(1e-12));
    CHECK_FALSE(ri.lo_open);
    CHECK(ri.hi == 0.8);
    CHECK(ri.hi_open);
  }
  SECTION("the best point outermost: the centre is that point, the root taken from its NLL") {
    // Points 0, 0.5, 1.0 of a parabola centred at 1.2: NLL(0.5) - NLL(1.0) =
    // 40 (0.49 - 0.04) = 18, root 6, so the lower end is 1.0 - 0.5 z / 6, z =
    // 1.959963984540054 (scipy.stats.norm.isf(0.025)).
    auto g = [](double x) { return 3.0 + 40.0 * (x - 1.2) * (x - 1.2); };
    const std::vector<double> x = {0.0, 0.5, 1.0}, y = {g(0.0), g(0.5), g(1.0)};
    const auto ri = stats::signed_root_interval(x, y);
    REQUIRE(ri.valid);
    CHECK(ri.lo == Approx(1.0 - 0.5 * 1.959963984540054 / 6.0).epsilon(1e-12));
    CHECK(ri.hi == 1.0);
    CHECK(ri.hi_open);
  }
  SECTION("fewer than two finite points: none") {
    const std::vector<double> x = {0.1, 0.2}, y = {1.0, std::numeric_limits<double>::quiet_NaN()};
    CHECK_FALSE(stats::signed_root_interval(x, y).valid);
  }
}

TEST_CASE("stats: parabola_vertex finds the vertex of the parabola through three points") {
  // f(x) = 3 (x − 1.3)² + 2 (vertex 1.3), at unequal spacings and in any order.
  auto f = [](double x) { return 3.0 * (x - 1.3) * (x - 1.3) + 2.0; };
  CHECK(stats::parabola_vertex(0.0, f(0.0), 1.0, f(1.0), 2.5, f(2.5)) == Approx(1.3).epsilon(1e-12));
  CHECK(stats::parabola_vertex(2.5, f(2.5), 0.0, f(0.0), 1.0, f(1.0)) == Approx(1.3).epsilon(1e-12));
  // The reflex's delay grid: 25, 30, 35 ms around a vertex at 32.8 ms.
  auto g = [](double x) { return -40.0 * (x - 0.0328) * (x - 0.0328); };
  CHECK(stats::parabola_vertex(0.025, g(0.025), 0.030, g(0.030), 0.035, g(0.035)) == Approx(0.0328).epsilon(1e-9));
  CHECK(std::isnan(stats::parabola_vertex(0.0, 1.0, 1.0, 2.0, 2.0, 3.0)));  // collinear
  CHECK(std::isnan(stats::parabola_vertex(1.0, 1.0, 1.0, 1.0, 2.0, 3.0)));  // two abscissae coincide
}
