#pragma once
// Reports as CSV in tidy long form: one row per (log, method, level, trial or
// angle, parameter), typed columns, SI values with the unit in its own
// column (layout in docs/estimator.md, "CSV").
#include <string>
#include <utility>
#include <vector>

#include "manip/estimation/session_estimator.hpp"

namespace manip::estimation {

// The CSV text (header included).
std::string csv_text(const std::vector<std::pair<std::string, Report>>& reports);
// Through AtomicOutput: refuses an existing file unless force; throws
// manip::OutputError naming the file; nothing left behind on failure.
void write_csv(const std::vector<std::pair<std::string, Report>>& reports, const std::string& path, bool force);

}  // namespace manip::estimation
