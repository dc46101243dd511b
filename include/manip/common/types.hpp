#pragma once
// Small value types shared by every module. SI units throughout.
#include <Eigen/Core>

namespace manip {

using Vec2 = Eigen::Vector2d;
using Mat2 = Eigen::Matrix2d;

}  // namespace manip
