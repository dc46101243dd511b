#pragma once
// Per-trial variational signals as CSV (needs EstimatorSettings::keep_windows).
#include <string>

#include "manip/estimation/session_estimator.hpp"

namespace manip::estimation {

// Per trial: t, Δx, Δẋ, Δẍ, Δu_ext (admittance and sensor), u_pert. Throws manip::OutputError.
void export_signals(const Report& r, const std::string& dir);

}  // namespace manip::estimation
