#include "manip/dsp/integrate.hpp"

#include <stdexcept>
#include <string>

namespace manip::dsp {

void cumulative_trapezoid(std::span<const double> y, double dx, std::span<double> out) {
  if (out.size() != y.size())
    throw std::invalid_argument("cumulative_trapezoid: output length " + std::to_string(out.size()) +
                                " != input length " + std::to_string(y.size()));
  if (y.empty()) return;
  // scipy: np.cumsum(dx * (y[1:] + y[:-1]) / 2.0) with 0 prepended; keeping
  // the same grouping makes the result bit-identical. y[i-1] is carried in a
  // local so that out may alias y.
  double prev = y[0];
  double acc = 0.0;
  out[0] = 0.0;
  for (std::size_t i = 1; i < y.size(); ++i) {
    const double cur = y[i];
    acc += dx * (cur + prev) / 2.0;
    out[i] = acc;
    prev = cur;
  }
}

}  // namespace manip::dsp
