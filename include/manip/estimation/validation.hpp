#pragma once
// Validation of the isolated variational dynamics against a simulator's twin
// truth (paper §4.3, Fig. 4): NRMSE(Δt) = RMS(estimate - truth over [0, Δt])
// / max |truth| over [0, T_norm], per axis, for Δx, Δẋ, Δẍ and Δu_ext.
#include <array>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "manip/estimation/variational.hpp"

namespace manip::estimation {

struct NrmseCurves {
  static constexpr std::array<const char*, 4> kSignals{"dx", "dxd", "dxdd", "du_ext"};
  std::vector<double> dt_s;
  std::array<std::vector<Vec2>, 4> mean, std;  // per signal, per Δt, per axis (over trials)
  int n_trials{0};
  std::string isolation{"paper"};  // which isolation produced the estimates (text, JSON, plot title)
};

// Only windows carrying twin truth count. Throws std::invalid_argument if none does.
NrmseCurves nrmse_curves(const std::vector<VariationalWindow>& windows, double t_norm_s = 0.15, int n_points = 30,
                         const std::string& isolation = "paper");
nlohmann::json to_json(const NrmseCurves& c);
std::string format_text(const NrmseCurves& c);
// Draws nothing (the hand-written SVG is gone): Fig. 4 is drawn by
// python/manipplot from validation.json through render_plots (report/render.hpp).
// Kept only so manip_sim builds until it calls render_plots.
void write_nrmse_plot(const NrmseCurves& c, const std::string& svg_path);

}  // namespace manip::estimation
