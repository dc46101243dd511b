#pragma once
// The Table-1 text summary of a Report (what estimate_impedance prints).
#include <string>

#include "manip/estimation/session_estimator.hpp"

namespace manip::estimation {

std::string format_text(const Report& r, const std::string& log_name);

}  // namespace manip::estimation
