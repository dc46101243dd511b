#pragma once
// The one SVG line-plot writer of the estimator (report plots and the
// validation figure): no plotting dependency in the C++ tools.
#include <cmath>
#include <limits>
#include <string>
#include <vector>

namespace manip::estimation {

struct Series {
  std::string name;
  std::vector<double> x, y;
  std::string color;
  bool dashed{false};
};

struct PlotOptions {
  bool logy{false};  // plot 10 log10(y) in dB
  double xmax{std::numeric_limits<double>::quiet_NaN()};  // clip x beyond this
  bool y_from_zero{false};  // y axis starts at 0 (else at the data minimum)
};

// Throws manip::OutputError if the file cannot be written.
void svg_plot(const std::string& path, const std::string& title, const std::string& xlabel, const std::string& ylabel,
              const std::vector<Series>& series, const PlotOptions& opt = {});

}  // namespace manip::estimation
