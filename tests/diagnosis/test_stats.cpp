// Distribution functions and tests against scipy/numpy (fixture script:
// tests/fixtures/diagnosis/make_fixtures.py), and Holm's procedure against
// a hand-worked example.
#include <catch2/catch.hpp>
#include <fstream>
#include <sstream>
#include <string>

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
