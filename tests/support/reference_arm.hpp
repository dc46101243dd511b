#pragma once
// The reference person of the estimation tests: paper Table 1 means (K
// symmetrised), an M_BSP near the trigger point, the manipulandum's
// admittance (M_adm + handle, D_adm).
#include "manip/common/types.hpp"

namespace manip::testutil {

inline const Mat2 kD = (Mat2() << 10.98, -7.94, -8.54, 6.75).finished();
inline const Mat2 kK = (Mat2() << 110.52, -106.05, -106.05, 313.75).finished();
inline const Mat2 kM = (Mat2() << 1.52, -0.82, -0.82, 1.41).finished();
inline const Mat2 kMdev = Mat2::Identity() * 5.3;
inline const Mat2 kDadm = Mat2::Identity() * 15.0;

}  // namespace manip::testutil
