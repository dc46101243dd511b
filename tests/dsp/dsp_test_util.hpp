#pragma once
// Helpers shared by the manip::dsp tests: fixture parsing and error measures.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "fixtures.hpp"

namespace manip::dsp::test {

// Sequential reader over a fixture's numbers.
class Numbers {
 public:
  explicit Numbers(const std::string& file) : v_(manip::testutil::read_numbers(file)), name_(file) {}
  double next() {
    if (pos_ >= v_.size()) throw std::runtime_error("fixture " + name_ + " ended early");
    return v_[pos_++];
  }
  int next_int() { return static_cast<int>(next()); }
  std::vector<double> take(std::size_t n) {
    std::vector<double> out(n);
    for (auto& x : out) x = next();
    return out;
  }
  [[nodiscard]] bool done() const { return pos_ == v_.size(); }

 private:
  std::vector<double> v_;
  std::string name_;
  std::size_t pos_ = 0;
};

// Signals stored as (scale, n, integers): sample = integer * scale, exactly the
// doubles numpy filtered.
inline std::vector<double> quantised_signal(const std::string& file) {
  Numbers in(file);
  const double scale = in.next();
  const auto n = static_cast<std::size_t>(in.next());
  std::vector<double> x(n);
  for (auto& v : x) v = in.next() * scale;
  if (!in.done()) throw std::runtime_error("trailing numbers in " + file);
  return x;
}

inline double peak(std::span<const double> v) {
  double m = 0.0;
  for (double x : v) m = std::max(m, std::fabs(x));
  return m;
}

// max_i |got_i - want_i| / max(|want_i|, floor_frac * max|want|): relative
// error, except that values smaller than floor_frac of the peak (zero
// crossings, bins far down a spectrum) are measured against floor_frac * peak,
// where only absolute accuracy is meaningful.
inline double rel_error(std::span<const double> got, std::span<const double> want, double floor_frac = 1e-3) {
  if (got.size() != want.size()) throw std::runtime_error("rel_error: size mismatch");
  const double floor = floor_frac * peak(want);
  double e = 0.0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const double denom = std::max(std::fabs(want[i]), floor);
    if (denom == 0.0) {
      e = std::max(e, std::fabs(got[i]));  // both should be exactly zero
    } else {
      e = std::max(e, std::fabs(got[i] - want[i]) / denom);
    }
  }
  return e;
}

// Normwise: max |got - want| / max |want|.
inline double norm_error(std::span<const double> got, std::span<const double> want) {
  double e = 0.0;
  for (std::size_t i = 0; i < got.size(); ++i) e = std::max(e, std::fabs(got[i] - want[i]));
  const double p = peak(want);
  return p > 0.0 ? e / p : e;
}

// Returns e; with MANIP_DSP_REPORT set in the environment also prints it, so
// that `MANIP_DSP_REPORT=1 test_dsp` lists every observed error vs scipy.
inline double observed(const std::string& what, double e) {
  if (std::getenv("MANIP_DSP_REPORT")) std::printf("  %-60s %.2e\n", what.c_str(), e);
  return e;
}

}  // namespace manip::dsp::test
