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

#include <algorithm>
#include <vector>

namespace manip::estimation::report_detail {

// 4 significant digits; scientific notation outside [1e-3, 1e6) so a cell
// never grows without bound; "n/a" for NaN/inf (docs/report.md, text tables).
inline std::string num(double v) {
  if (!std::isfinite(v)) return "n/a";
  const double a = std::abs(v);
  std::ostringstream o;
  if (a != 0.0 && (a < 1e-3 || a >= 1e6)) {
    o << std::scientific << std::setprecision(3) << v;
  } else {
    const int digits = a == 0.0 ? 0 : static_cast<int>(std::floor(std::log10(a))) + 1;
    o << std::fixed << std::setprecision(std::clamp(4 - digits, 0, 6)) << v;
  }
  return o.str();
}

// "est [lo, hi]" (the interval left out when not finite).
inline std::string with_interval(double est, double lo, double hi) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) return num(est);
  return num(est) + " [" + num(lo) + ", " + num(hi) + "]";
}

// A text table whose columns are as wide as their widest cell plus two
// spaces: columns can never fuse, whatever the numbers.
class TextTable {
 public:
  explicit TextTable(std::vector<std::string> header) : rows_{std::move(header)} {}
  void add(std::vector<std::string> row) { rows_.push_back(std::move(row)); }
  [[nodiscard]] std::string str(const std::string& indent = "    ") const {
    std::vector<std::size_t> w;
    for (const auto& r : rows_)
      for (std::size_t c = 0; c < r.size(); ++c) {
        if (w.size() <= c) w.push_back(0);
        w[c] = std::max(w[c], r[c].size());
      }
    std::ostringstream o;
    for (const auto& r : rows_) {
      std::string line = indent;
      for (std::size_t c = 0; c < r.size(); ++c) {
        // First column left-aligned (labels), the others right-aligned (numbers).
        const std::string pad(w[c] - r[c].size(), ' ');
        line += c == 0 ? r[c] + pad : pad + r[c];
        if (c + 1 < r.size()) line += "  ";
      }
      while (!line.empty() && line.back() == ' ') line.pop_back();
      o << line << "\n";
    }
    return o.str();
  }

 private:
  std::vector<std::vector<std::string>> rows_;
};

// Element labels of a 2x2, row-major: D11 D12 D21 D22.
inline std::string element(const char* m, int i) { return std::string(m) + std::to_string(i / 2 + 1) + std::to_string(i % 2 + 1); }

}  // namespace manip::estimation::report_detail
