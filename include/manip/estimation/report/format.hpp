#pragma once
// Number formatting shared by the report writers.
#include <cmath>
#include <iomanip>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "manip/common/types.hpp"

namespace manip::estimation::report_detail {

// Fixed-point text, "n/a" for NaN/inf.
inline std::string fmt(double v, int prec = 2) {
  if (!std::isfinite(v)) return "n/a";
  std::ostringstream o;
  o << std::fixed << std::setprecision(prec) << v;
  return o.str();
}

// Row-major 2x2 as a JSON array, null for NaN/inf.
inline nlohmann::json mat(const Mat2& m) {
  auto f = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return nlohmann::json::array({f(m(0, 0)), f(m(0, 1)), f(m(1, 0)), f(m(1, 1))});
}

}  // namespace manip::estimation::report_detail

#include <filesystem>
#include <system_error>

#include "manip/common/errors.hpp"

namespace manip::estimation::report_detail {

// Creates an output directory; manip::OutputError naming it if that fails.
inline void create_output_dir(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw manip::OutputError(dir + ": cannot create directory (" + ec.message() + ")");
}

}  // namespace manip::estimation::report_detail
