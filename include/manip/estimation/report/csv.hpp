#pragma once
// Reports as CSV: one row per summary and per (method, trial).
#include <string>
#include <utility>
#include <vector>

#include "manip/estimation/session_estimator.hpp"

namespace manip::estimation {

// Throws manip::OutputError naming the file.
void write_csv(const std::vector<std::pair<std::string, Report>>& reports, const std::string& path);

}  // namespace manip::estimation
