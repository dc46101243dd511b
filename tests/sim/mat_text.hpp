#pragma once
// A 2x2 matrix as one line of a test's INFO: "[a b; c d]".
#include <sstream>
#include <string>

#include "manip/common/types.hpp"

namespace sim_test {

inline std::string show(const manip::Mat2& m) {
  std::ostringstream o;
  o << "[" << m(0, 0) << " " << m(0, 1) << "; " << m(1, 0) << " " << m(1, 1) << "]";
  return o.str();
}

}  // namespace sim_test
