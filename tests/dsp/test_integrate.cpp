#include <catch2/catch.hpp>

#include <stdexcept>

#include "dsp_test_util.hpp"
#include "manip/dsp/integrate.hpp"

using manip::dsp::cumulative_trapezoid;

TEST_CASE("cumulative_trapezoid: bit-identical to scipy on 2000 trial jerk samples") {
  const auto x = manip::dsp::test::quantised_signal("dsp/trial_jerk.txt");
  manip::dsp::test::Numbers in("dsp/cumtrapz_trial.txt");
  const double dx = in.next();
  const auto n = static_cast<std::size_t>(in.next());
  const auto want = in.take(n);
  std::vector<double> y(x.begin(), x.begin() + static_cast<std::ptrdiff_t>(n)), out(n);
  cumulative_trapezoid(y, dx, out);
  CHECK(out == want);
  cumulative_trapezoid(y, dx, y);  // in place
  CHECK(y == want);
}

TEST_CASE("cumulative_trapezoid: edge cases") {
  std::vector<double> one{5.0}, out1(1, 7.0);
  cumulative_trapezoid(one, 0.1, out1);
  CHECK(out1[0] == 0.0);
  std::vector<double> none, out0;
  cumulative_trapezoid(none, 0.1, out0);
  std::vector<double> lin{0.0, 1.0, 2.0, 3.0}, o(4);
  cumulative_trapezoid(lin, 0.5, o);
  CHECK(o == std::vector<double>{0.0, 0.25, 1.0, 2.25});
  std::vector<double> wrong(3);
  CHECK_THROWS_AS(cumulative_trapezoid(lin, 0.5, wrong), std::invalid_argument);
}
