// Verifies the "no allocation in the hot path" contract: SavgolFilter::apply
// never allocates, sosfiltfilt only grows its thread_local scratch, sosfilt
// and cumulative_trapezoid never allocate. The test executable replaces the
// global operator new with a counting one (only this module's tests link it).
#include <catch2/catch.hpp>

#include <cstdlib>
#include <new>

#include "dsp_test_util.hpp"
#include "manip/dsp/dsp.hpp"

namespace {
thread_local bool g_counting = false;
thread_local long g_allocs = 0;
}  // namespace

// Every unaligned form is replaced, so that all of them pair malloc with free
// (ASan reports new/free mismatches if e.g. the nothrow form, used by
// std::stable_sort's temporary buffer, were left to the runtime).
namespace {
void* counted_malloc(std::size_t n) noexcept {
  if (g_counting) ++g_allocs;
  return std::malloc(n == 0 ? 1 : n);
}
}  // namespace

void* operator new(std::size_t n) {
  if (void* p = counted_malloc(n)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  if (void* p = counted_malloc(n)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return counted_malloc(n); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return counted_malloc(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }

namespace {
template <class F>
long count_allocs(F&& f) {
  g_allocs = 0;
  g_counting = true;
  f();
  g_counting = false;
  return g_allocs;
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
