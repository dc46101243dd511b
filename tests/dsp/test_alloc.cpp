// Verifies the "no allocation in the hot path" contract: SavgolFilter::apply
// never allocates, sosfiltfilt only grows its thread_local scratch, sosfilt
// and cumulative_trapezoid never allocate (tests/support/alloc_counter.hpp).
#include <catch2/catch.hpp>

#include "alloc_counter.hpp"
#include "dsp_test_util.hpp"
#include "manip/dsp/dsp.hpp"

namespace {
template <class F>
long count_allocs(F&& f) {
  const manip::test::ThreadAllocScope scope;
  f();
  return scope.news();
}
}  // namespace

TEST_CASE("hot path does not allocate") {
  using namespace manip::dsp;
  const auto x = test::quantised_signal("dsp/trial_jerk.txt");
  std::vector<double> y(x.size()), z(x.size());
  const SavgolFilter sg(225, 5, 3, 1.0 / 4000.0);
  const auto hp = butter(5, 1.0, 4000.0, BandType::highpass);
  std::vector<double> zi = sosfilt_zi(hp);
  sosfiltfilt(hp, x, y);  // sizes the scratch for this length

  CHECK(count_allocs([&] { sg.apply(x, y); }) == 0);
  CHECK(count_allocs([&] { sosfiltfilt(hp, x, y); }) == 0);
  CHECK(count_allocs([&] { sosfiltfilt(hp, std::span<const double>(x.data(), 5000), std::span<double>(y.data(), 5000)); }) == 0);
  CHECK(count_allocs([&] { sosfilt(hp, x, y); }) == 0);
  CHECK(count_allocs([&] { sosfilt(hp, x, y, zi); }) == 0);
  CHECK(count_allocs([&] { cumulative_trapezoid(x, 2.5e-4, z); }) == 0);
  // The counter works.
  CHECK(count_allocs([&] { std::vector<double> v(10); (void)v; }) == 1);
}
