#pragma once
// The report's figures as SVG (through report/svg.hpp).
#include <string>

#include "manip/estimation/session_estimator.hpp"

namespace manip::estimation {

// Fig. 3 (PSDs), Fig. 5 (variational dynamics per trial), D and K per angle. Throws manip::OutputError.
void write_plots(const Report& r, const std::string& dir);

}  // namespace manip::estimation
