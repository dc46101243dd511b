#include "manip/estimation/report/plots.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

#include "manip/common/errors.hpp"
#include "manip/estimation/report/format.hpp"
#include "manip/estimation/report/svg.hpp"

namespace manip::estimation {

using report_detail::fmt;
using report_detail::mat;
using report_detail::create_output_dir;

void write_plots(const Report& r, const std::string& dir) {
  create_output_dir(dir);
  if (!r.psd.f_hz.empty()) {
    std::vector<Series> s;
    if (r.psd.n_unperturbed) s.push_back({"unperturbed", r.psd.f_hz, r.psd.p_unperturbed, "#1f77b4"});
    if (r.psd.n_perturbed) s.push_back({"perturbed", r.psd.f_hz, r.psd.p_perturbed, "#d62728"});
    svg_plot(dir + "/psd_jerk_x2.svg", "PSD of principal-axis jerk (Fig. 3)", "f [Hz]", "PSD [(m/s^3)^2/Hz]", s, {.logy = true, .xmax = 10.0});
  }
  for (const auto& w : r.windows) {
    std::vector<double> t(w.size());
    for (std::size_t k = 0; k < w.size(); ++k) t[k] = static_cast<double>(k) / w.fs_hz * 1000.0;
    auto comp = [&](const std::vector<Vec2>& v, int a, double scale) {
      std::vector<double> y(v.size());
      for (std::size_t k = 0; k < v.size(); ++k) y[k] = v[k](a) * scale;
      return y;
    };
    std::vector<Series> s{{"dx1 [mm]", t, comp(w.dx, 0, 1e3), "#1f77b4"},
                          {"dx2 [mm]", t, comp(w.dx, 1, 1e3), "#ff7f0e"},
                          {"du_ext1 [N]/10", t, comp(w.du_ext_adm, 0, 0.1), "#2ca02c"},
                          {"du_ext2 [N]/10", t, comp(w.du_ext_adm, 1, 0.1), "#d62728"}};
    if (!w.dx_true.empty()) {
      s.push_back({"true dx1 [mm]", t, comp(w.dx_true, 0, 1e3), "#9467bd"});
      s.push_back({"true dx2 [mm]", t, comp(w.dx_true, 1, 1e3), "#8c564b"});
    }
    svg_plot(dir + "/trial_" + std::to_string(w.trial) + "_variational.svg",
             "Trial " + std::to_string(w.trial) + " variational dynamics (Fig. 5)", "t after onset [ms]", "value", s);
  }
  // D and K per angle for each method.
  std::set<std::string> methods;
  for (const auto& s : r.summaries) methods.insert(s.method);
  for (const auto& m : methods) {
    std::vector<double> ang;
    std::vector<std::vector<double>> dv(4), kv(4);
    for (const auto& s : r.summaries) {
      if (s.method != m || !s.group.is_angle()) continue;
      ang.push_back(s.group.angle_deg);
      for (int i = 0; i < 4; ++i) {
        dv[static_cast<std::size_t>(i)].push_back(s.d_nspm(i / 2, i % 2));
        kv[static_cast<std::size_t>(i)].push_back(s.k_npm(i / 2, i % 2));
      }
    }
    if (ang.empty()) continue;
    const char* names[4] = {"11", "12", "21", "22"};
    const char* colors[4] = {"#1f77b4", "#ff7f0e", "#2ca02c", "#d62728"};
    std::vector<Series> sd, sk;
    for (int i = 0; i < 4; ++i) {
      sd.push_back({std::string("D") + names[i], ang, dv[static_cast<std::size_t>(i)], colors[i]});
      sk.push_back({std::string("K") + names[i], ang, kv[static_cast<std::size_t>(i)], colors[i]});
    }
    svg_plot(dir + "/" + m + "_D_per_angle.svg", "D per perturbation angle (" + m + ")", "angle [deg]", "D [Ns/m]", sd);
    svg_plot(dir + "/" + m + "_K_per_angle.svg", "K per perturbation angle (" + m + ")", "angle [deg]", "K [N/m]", sk);
  }
}

}  // namespace manip::estimation
