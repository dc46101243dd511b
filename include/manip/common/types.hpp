#pragma once
// Small value types shared by every module. SI units throughout.
// Dense (not Core): 2x2 inverse/determinant/ldlt are used everywhere.
#include <Eigen/Dense>

namespace manip {

using Vec2 = Eigen::Vector2d;
using Mat2 = Eigen::Matrix2d;

}  // namespace manip
