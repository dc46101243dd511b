#pragma once
// A Report as JSON (layout in docs/estimator.md).
#include <string>

#include <nlohmann/json.hpp>

#include "manip/estimation/session_estimator.hpp"

namespace manip::estimation {

nlohmann::json to_json(const Report& r, const std::string& log_name);

}  // namespace manip::estimation
