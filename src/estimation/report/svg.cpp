#include "manip/estimation/report/svg.hpp"

#include <algorithm>
#include <fstream>

#include "manip/common/errors.hpp"
#include "manip/estimation/report/format.hpp"

namespace manip::estimation {

using report_detail::fmt;

void svg_plot(const std::string& path, const std::string& title, const std::string& xlabel, const std::string& ylabel,
              const std::vector<Series>& series, const PlotOptions& opt) {
  const bool logy = opt.logy;
  const double xmax = opt.xmax;
  const double W = 640, H = 400, L = 70, R = 150, T = 40, B = 50;
  double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
  auto ty = [&](double v) { return logy ? 10.0 * std::log10(std::max(v, 1e-300)) : v; };
  for (const auto& s : series)
    for (std::size_t i = 0; i < s.x.size(); ++i) {
      if (std::isfinite(xmax) && s.x[i] > xmax) continue;
      const double yy = ty(s.y[i]);
      if (!std::isfinite(yy)) continue;
      x0 = std::min(x0, s.x[i]);
      x1 = std::max(x1, s.x[i]);
      y0 = std::min(y0, yy);
      y1 = std::max(y1, yy);
    }
  if (!(x1 > x0)) x1 = x0 + 1;
  if (!(y1 > y0)) y1 = y0 + 1;
  if (logy) y0 = std::max(y0, y1 - 80.0);
  if (opt.y_from_zero) y0 = std::min(y0, 0.0);
  const double pad = 0.05 * (y1 - y0);
  y0 -= pad;
  y1 += pad;
  auto px = [&](double x) { return L + (x - x0) / (x1 - x0) * (W - L - R); };
  auto py = [&](double y) { return T + (y1 - std::clamp(y, y0, y1)) / (y1 - y0) * (H - T - B); };
  std::ofstream o(path);
  if (!o) throw manip::OutputError(path + ": cannot write plot");
  o << "<svg xmlns='http://www.w3.org/2000/svg' width='" << W << "' height='" << H << "' font-family='sans-serif' font-size='12'>\n";
  o << "<rect width='100%' height='100%' fill='white'/>\n";
  o << "<text x='" << W / 2 << "' y='20' text-anchor='middle' font-size='14'>" << title << "</text>\n";
  o << "<rect x='" << L << "' y='" << T << "' width='" << W - L - R << "' height='" << H - T - B << "' fill='none' stroke='black'/>\n";
  for (int i = 0; i <= 4; ++i) {
    const double xv = x0 + i * (x1 - x0) / 4, yv = y0 + i * (y1 - y0) / 4;
    o << "<text x='" << px(xv) << "' y='" << H - B + 15 << "' text-anchor='middle'>" << fmt(xv, 3) << "</text>\n";
    o << "<text x='" << L - 5 << "' y='" << py(yv) + 4 << "' text-anchor='end'>" << fmt(yv, 3) << "</text>\n";
  }
  o << "<text x='" << (L + W - R) / 2 << "' y='" << H - 12 << "' text-anchor='middle'>" << xlabel << "</text>\n";
  o << "<text x='15' y='" << (T + H - B) / 2 << "' transform='rotate(-90 15 " << (T + H - B) / 2
    << ")' text-anchor='middle'>" << (logy ? ylabel + " [dB]" : ylabel) << "</text>\n";
  int li = 0;
  for (const auto& s : series) {
    o << "<polyline fill='none' stroke='" << s.color << "' stroke-width='1.2'" << (s.dashed ? " stroke-dasharray='4,3'" : "")
      << " points='";
    for (std::size_t i = 0; i < s.x.size(); ++i) {
      if (std::isfinite(xmax) && s.x[i] > xmax) break;
      const double yy = ty(s.y[i]);
      if (std::isfinite(yy)) o << px(s.x[i]) << ',' << py(yy) << ' ';
    }
    o << "'/>\n";
    o << "<text x='" << W - R + 10 << "' y='" << T + 15 + 16 * li << "' fill='" << s.color << "'>" << s.name << "</text>\n";
    ++li;
  }
  o << "</svg>\n";
}


}  // namespace manip::estimation
