// The JSON "traces" of a diagnosis (report.hpp): held-out predictions of the
// baseline and of the extended model, laid out for the figures.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>

#include "manip/diagnosis/report.hpp"

namespace manip::diagnosis {
namespace {

double vaf_of(const std::vector<double>& y, const std::vector<double>& yhat) {
  double m = 0.0;
  for (double v : y) m += v;
  m /= static_cast<double>(y.size());
  double sse = 0.0, sst = 0.0;
  for (std::size_t i = 0; i < y.size(); ++i) {
    sse += (y[i] - yhat[i]) * (y[i] - yhat[i]);
    sst += (y[i] - m) * (y[i] - m);
  }
  return sst > 0 ? 1.0 - sse / sst : 0.0;
}

}  // namespace

nlohmann::json traces_json(const Dataset& d, const Diagnosis& res) {
  const auto& blocks = res.predictions.spans;
  const int folds = res.folds;
  const bool extended = res.misfit_found() && !res.predictions.extended.empty();
  const auto& p0 = res.predictions.baseline;
  const auto& p1 = extended ? res.predictions.extended : res.predictions.baseline;
  if (p0.empty()) throw std::logic_error("traces_json: the diagnosis kept no predictions (EngineOptions::keep_predictions)");
  // Consistency: the fold VAFs recomputed from the predictions equal the
  // report's (tests check the flag).
  const auto fold_vaf = [&](const std::vector<std::vector<double>>& pred) {
    std::vector<double> v;
    for (int k = 0; k < folds; ++k) {
      std::vector<double> yy, hh;
      for (const auto& b : blocks)
        if (b.fold == k)
          for (std::size_t i = b.begin; i < b.end; ++i) {
            yy.push_back(d.segments[b.seg].y[i]);
            hh.push_back(pred[b.seg][i]);
          }
      v.push_back(vaf_of(yy, hh));
    }
    return v;
  };
  const auto same = [](const std::vector<double>& a, const std::vector<double>& b) {
    if (a.size() != b.size()) return false;
    for (std::size_t i = 0; i < a.size(); ++i)
      if (std::fabs(a[i] - b[i]) > 1e-6) return false;
    return true;
  };
  const bool matches = same(fold_vaf(p0), res.baseline_heldout.fold_vaf) && (!extended || same(fold_vaf(p1), res.final_heldout.fold_vaf));
  const auto opt = [&](const std::vector<double>& v) { return extended ? nlohmann::json(v) : nlohmann::json(nullptr); };
  nlohmann::json t;
  t["prediction"] =
      "held-out: each sample predicted by the model fitted on the other folds (the engine's folds; the last accepted mechanism's "
      "shape chosen per fold on the training folds, as the engine scores it)";
  t["unit"] = d.target_unit;
  t["extended_model"] = res.accepted;
  t["matches_engine_folds"] = matches;
  if (!d.is_planar()) {
    std::vector<std::size_t> idx(res.baseline_heldout.fold_vaf.size());
    std::iota(idx.begin(), idx.end(), 0);
    std::sort(idx.begin(), idx.end(), [&](auto a, auto b) { return res.baseline_heldout.fold_vaf[a] < res.baseline_heldout.fold_vaf[b]; });
    const int fold = idx.empty() ? 0 : static_cast<int>(idx[idx.size() / 2]);
    std::vector<double> ts, y, b0, b1;
    const auto max_n = static_cast<std::size_t>(std::ceil(3.0 / d.dt_s));
    for (const auto& b : blocks) {
      if (b.fold != fold) continue;
      const auto& g = d.segments[b.seg];
      for (std::size_t i = b.begin; i < b.end && ts.size() < max_n; ++i) {
        ts.push_back(g.t0_s + static_cast<double>(i) * d.dt_s);
        y.push_back(g.y[i]);
        b0.push_back(p0[b.seg][i]);
        b1.push_back(p1[b.seg][i]);
      }
    }
    t["kind"] = "single_joint";
    t["fold"] = fold;
    t["t_s"] = ts;
    t["measured"] = y;
    t["baseline"] = b0;
    t["extended"] = opt(b1);
    t["vaf_baseline"] = vaf_of(y, b0);
    t["vaf_extended"] = extended ? nlohmann::json(vaf_of(y, b1)) : nlohmann::json(nullptr);
    return t;
  }
  // Manipulandum: segments (trial, axis); the window after onset shared by all.
  std::size_t n = std::numeric_limits<std::size_t>::max();
  for (const auto& b : blocks) n = std::min(n, b.end);
  std::size_t k0 = std::numeric_limits<std::size_t>::max();
  for (const auto& b : blocks) k0 = std::min(k0, b.begin);
  std::vector<double> ts;
  for (std::size_t k = k0; k < n; ++k) ts.push_back(static_cast<double>(k) * d.dt_s);
  t["kind"] = "manipulandum";
  t["t_after_onset_s"] = ts;
  const auto band = [&](const std::vector<std::vector<double>>& pred, nlohmann::json& mean_out, nlohmann::json& half_out) {
    mean_out = nlohmann::json::array();
    half_out = nlohmann::json::array();
    for (int axis = 0; axis < 2; ++axis) {
      std::vector<double> mean(ts.size(), 0.0), sq(ts.size(), 0.0), half(ts.size(), 0.0);
      double cnt = 0;
      for (std::size_t s = 0; s < d.segments.size(); ++s) {
        if (d.segments[s].axis != axis) continue;
        cnt += 1;
        for (std::size_t k = k0; k < n; ++k) {
          const double e = d.segments[s].y[k] - pred[s][k];
          mean[k - k0] += e;
          sq[k - k0] += e * e;
        }
      }
      for (std::size_t i = 0; i < ts.size(); ++i) {
        mean[i] /= cnt;
        const double var = cnt > 1 ? std::max(0.0, (sq[i] - cnt * mean[i] * mean[i]) / (cnt - 1)) : 0.0;
        half[i] = 1.96 * std::sqrt(var / cnt);
      }
      mean_out.push_back(mean);
      half_out.push_back(half);
    }
  };
  t["n_trials"] = d.planar.size();
  band(p0, t["mean_residual_before"], t["ci95_halfwidth_before"]);
  if (extended) {
    band(p1, t["mean_residual_after"], t["ci95_halfwidth_after"]);
  } else {
    t["mean_residual_after"] = nullptr;
    t["ci95_halfwidth_after"] = nullptr;
  }
  std::vector<int> picks{0, static_cast<int>(d.planar.size()) / 2, static_cast<int>(d.planar.size()) - 1};
  picks.erase(std::unique(picks.begin(), picks.end()), picks.end());
  t["trials"] = nlohmann::json::array();
  for (int g : picks) {
    nlohmann::json jt = {{"trial", d.planar[static_cast<std::size_t>(g)].trial}, {"log", d.planar[static_cast<std::size_t>(g)].log}};
    nlohmann::json y = nlohmann::json::array(), b0 = nlohmann::json::array(), b1 = nlohmann::json::array();
    for (int axis = 0; axis < 2; ++axis)
      for (std::size_t s = 0; s < d.segments.size(); ++s)
        if (d.segments[s].group == g && d.segments[s].axis == axis) {
          const auto& seg = d.segments[s];
          y.push_back(std::vector<double>(seg.y.begin() + static_cast<long>(k0), seg.y.begin() + static_cast<long>(n)));
          b0.push_back(std::vector<double>(p0[s].begin() + static_cast<long>(k0), p0[s].begin() + static_cast<long>(n)));
          b1.push_back(std::vector<double>(p1[s].begin() + static_cast<long>(k0), p1[s].begin() + static_cast<long>(n)));
        }
    jt["target"] = y;
    jt["baseline"] = b0;
    jt["extended"] = extended ? b1 : nlohmann::json(nullptr);
    t["trials"].push_back(jt);
  }
  return t;
}

}  // namespace manip::diagnosis
