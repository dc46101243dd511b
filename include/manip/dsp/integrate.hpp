#pragma once
// Numerical integration. The paper obtains the variational acceleration,
// velocity and position from the high-pass-filtered jerk "by integration";
// over the short estimation interval the drift of the trapezoidal rule is
// negligible.
#include <span>

namespace manip::dsp {

// scipy.integrate.cumulative_trapezoid(y, dx=dx, initial=0), bit-identical:
// out[0] = 0, out[i] = out[i-1] + dx * (y[i-1] + y[i]) / 2 summed left to
// right exactly like numpy's cumsum. out.size() must equal y.size(), else
// std::invalid_argument. out may be the same memory as y (in-place).
void cumulative_trapezoid(std::span<const double> y, double dx, std::span<double> out);

}  // namespace manip::dsp
