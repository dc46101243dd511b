#pragma once
// A portable random generator for everything a recorded seed must reproduce
// (trial schedule, re-queue positions, simulated participant): SplitMix64 with
// our own bounded-integer, uniform and normal draws. std::shuffle and the std
// distributions are implementation-defined, so the same seed could give a
// different schedule with another standard library. Never allocates.
#include <cmath>
#include <cstdint>
#include <numbers>

namespace manip {

class PortableRng {
 public:
  explicit PortableRng(std::uint64_t seed = 0) : s_(seed) {}
  void seed(std::uint64_t s) { s_ = s; }

  std::uint64_t next() {
    std::uint64_t z = (s_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform integer in [0, n), n > 0 (rejection sampling: unbiased).
  std::uint64_t below(std::uint64_t n) {
    const std::uint64_t limit = ~std::uint64_t{0} - (~std::uint64_t{0} % n);
    std::uint64_t r;
    do r = next();
    while (r >= limit);
    return r % n;
  }
  // Uniform in [0, 1).
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  // Standard normal (Box-Muller, one value per call).
  double normal() {
    double u1 = uniform();
    if (u1 < 1e-300) u1 = 1e-300;
    const double u2 = uniform();
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  }

 private:
  std::uint64_t s_;
};

// Fisher-Yates with PortableRng.
template <class It>
void portable_shuffle(It first, It last, PortableRng& rng) {
  const auto n = static_cast<std::uint64_t>(last - first);
  for (std::uint64_t i = n; i > 1; --i) {
    const std::uint64_t j = rng.below(i);
    using std::swap;
    swap(first[static_cast<long>(i - 1)], first[static_cast<long>(j)]);
  }
}

}  // namespace manip
