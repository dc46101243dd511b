#pragma once
// Per-trial variational signals as CSV (needs EstimatorSettings::keep_windows).
#include <string>

#include "manip/estimation/session_estimator.hpp"

namespace manip::estimation {

// dir/trial_<k>.csv per trial: t, Δx, Δẋ, Δẍ, Δu_ext (admittance and
// sensor), u_pert, and for simulated logs the twin truth of Δx, Δẋ, Δẍ,
// Δu_ext (Fig. 4). Units in the column names. An existing trial file is
// refused unless force, before anything is written; each file is written
// atomically. Throws manip::OutputError naming the file.
void export_signals(const Report& r, const std::string& dir, bool force = false);

}  // namespace manip::estimation
