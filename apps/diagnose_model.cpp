// diagnose_model: what a model gets wrong on measured data, the likely cause,
// the extended model and its measured gain (docs/diagnosis.md).
// Thin main: options, the single-joint front end, the engine, the reports.
// Command line: common/cli.hpp (docs/cli.md): --version, -q, --force, the
// exit-code table in --help.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <numeric>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "manip/common/cli.hpp"
#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/common/output_file.hpp"
#include "manip/diagnosis/engine.hpp"
#include "manip/diagnosis/manipulandum.hpp"
#include "manip/diagnosis/report.hpp"
#include "manip/diagnosis/single_joint.hpp"
#include "manip/estimation/report/render.hpp"
#include "manip/version.hpp"

namespace {

namespace ec = manip::exit_code;
const std::vector<int> kExitCodes = {ec::kOk, ec::kUsage, ec::kInput, ec::kOutput, ec::kInternal};
const char* kExitNotes =
    "What the codes mean for diagnose_model (several: the most severe wins, docs/exit-codes.md):\n"
    "    0: diagnosis done, with or without a misfit found\n"
    "    2: bad command line (also: no input, or logs and --single-joint together)\n"
    "    4: an input is unusable: missing or unreadable, a malformed line (FILE:LINE: reason), too short for\n"
    "       the cross-validation or too few perturbed trials, logs with different configurations\n"
    "    6: the --json file exists or the --plots DIR is not empty (no --force; checked before any input is\n"
    "       read), an output cannot be written, or Python/matplotlib is missing for --plots; nothing is left\n"
    "       behind (the text report is printed and --json written before the figures are drawn)\n";

namespace fs = std::filesystem;
using manip::diagnosis::Columns;
using manip::diagnosis::Dataset;
using manip::diagnosis::Diagnosis;

// ---------------------------------------------------------------- held-out predictions for --plots / --json "traces"
// The engine's folds (engine.cpp, make_blocks): trials (segment groups) in
// time order, K folds of neighbouring trials; or one continuous record cut
// into K contiguous folds with a guard gap between them. A sample is
// predicted by the model fitted on the other folds (the held-out prediction
// the fold VAF and the gains are computed from).
struct PredBlock {
  std::size_t seg = 0, begin = 0, end = 0;
  int fold = 0;
};

std::vector<PredBlock> engine_folds(const Dataset& d, const manip::diagnosis::EngineOptions& opt, std::size_t history) {
  std::vector<PredBlock> out;
  const int K = opt.folds;
  const auto nseg = d.segments.size();
  std::vector<int> order;  // units in order of first appearance
  std::vector<std::size_t> rank(nseg);
  for (std::size_t s = 0; s < nseg; ++s) {
    const int key = d.segments[s].group >= 0 ? d.segments[s].group : -1 - static_cast<int>(s);
    auto it = std::find(order.begin(), order.end(), key);
    if (it == order.end()) {
      order.push_back(key);
      it = order.end() - 1;
    }
    rank[s] = static_cast<std::size_t>(it - order.begin());
  }
  if (order.size() >= static_cast<std::size_t>(K)) {
    for (std::size_t s = 0; s < nseg; ++s)
      out.push_back({s, d.segments[s].first + history, d.segments[s].last,
                     static_cast<int>(rank[s] * static_cast<std::size_t>(K) / order.size())});
    return out;
  }
  const auto& g = d.segments.at(0);
  const auto guard = static_cast<std::size_t>(std::ceil(opt.guard_s / d.dt_s));
  const std::size_t lo = g.first + history, L = g.last - lo;
  for (int k = 0; k < K; ++k) {
    std::size_t a = lo + L * static_cast<std::size_t>(k) / static_cast<std::size_t>(K);
    std::size_t b = lo + L * static_cast<std::size_t>(k + 1) / static_cast<std::size_t>(K);
    if (k > 0) a += guard / 2;
    if (k < K - 1) b -= (guard + 1) / 2;
    out.push_back({0, a, b, k});
  }
  return out;
}

// As the engine's solve: column-scaled LDLT, minimum-norm fallback.
Eigen::VectorXd solve_scaled(const Eigen::MatrixXd& G, const Eigen::VectorXd& h) {
  const Eigen::Index p = G.rows();
  Eigen::VectorXd s(p);
  for (Eigen::Index i = 0; i < p; ++i) s(i) = G(i, i) > 0 ? 1.0 / std::sqrt(G(i, i)) : 1.0;
  const Eigen::MatrixXd Gs = s.asDiagonal() * G * s.asDiagonal();
  const Eigen::VectorXd hs = s.asDiagonal() * h;
  Eigen::LDLT<Eigen::MatrixXd> ldlt(Gs);
  const Eigen::VectorXd z = (ldlt.info() == Eigen::Success && ldlt.isPositive() && ldlt.rcond() > 1e-13)
                                ? Eigen::VectorXd(ldlt.solve(hs))
                                : Eigen::VectorXd(Gs.completeOrthogonalDecomposition().solve(hs));
  return s.asDiagonal() * z;
}

using ColsFn = std::function<std::vector<const std::vector<double>*>(std::size_t seg)>;

// The columns of a model: the baseline's, then each extra set's.
ColsFn model_cols(const Dataset& d, std::vector<const Columns*> extras) {
  return [&d, extras](std::size_t seg) {
    std::vector<const std::vector<double>*> c;
    for (const auto& b : d.segments[seg].base) c.push_back(&b);
    for (const auto* e : extras)
      for (const auto& col : (*e)[seg]) c.push_back(&col);
    return c;
  };
}

double dot(const std::vector<double>& a, const std::vector<double>& b, std::size_t lo, std::size_t hi) {
  const auto n = static_cast<Eigen::Index>(hi - lo);
  return Eigen::Map<const Eigen::VectorXd>(a.data() + lo, n).dot(Eigen::Map<const Eigen::VectorXd>(b.data() + lo, n));
}

// Normal equations per fold: G = X'X, h = X'y, yy = y'y over the fold's blocks.
struct FoldStats {
  Eigen::MatrixXd G;
  Eigen::VectorXd h;
  double yy = 0.0;
};

std::vector<FoldStats> fold_stats(const Dataset& d, const std::vector<PredBlock>& blocks, int folds, const ColsFn& cols) {
  const auto p = static_cast<Eigen::Index>(cols(0).size());
  std::vector<FoldStats> fs(static_cast<std::size_t>(folds), FoldStats{Eigen::MatrixXd::Zero(p, p), Eigen::VectorXd::Zero(p), 0.0});
  for (const auto& b : blocks) {
    const auto c = cols(b.seg);
    const auto& y = d.segments[b.seg].y;
    auto& f = fs[static_cast<std::size_t>(b.fold)];
    for (Eigen::Index i = 0; i < p; ++i) {
      const auto& ci = *c[static_cast<std::size_t>(i)];
      for (Eigen::Index j = 0; j <= i; ++j) {
        const double v = dot(ci, *c[static_cast<std::size_t>(j)], b.begin, b.end);
        f.G(i, j) += v;
        if (j != i) f.G(j, i) += v;
      }
      f.h(i) += dot(ci, y, b.begin, b.end);
    }
    f.yy += dot(y, y, b.begin, b.end);
  }
  return fs;
}

FoldStats training(const std::vector<FoldStats>& fs, int k) {
  FoldStats t{Eigen::MatrixXd::Zero(fs[0].G.rows(), fs[0].G.cols()), Eigen::VectorXd::Zero(fs[0].h.size()), 0.0};
  for (std::size_t j = 0; j < fs.size(); ++j)
    if (static_cast<int>(j) != k) {
      t.G += fs[j].G;
      t.h += fs[j].h;
      t.yy += fs[j].yy;
    }
  return t;
}

// The engine's held-out evaluation of the last mechanism added (engine.cpp,
// greedy search): its shape setting is chosen per fold, by the smallest
// training SSE (the test fold never chooses it); the mechanisms added before
// it keep their full-data settings. Returns the grid index per fold.
std::vector<std::size_t> per_fold_settings(const Dataset& d, const std::vector<PredBlock>& blocks, int folds,
                                           const std::vector<const Columns*>& fixed, const manip::diagnosis::Mechanism& m) {
  const auto base = fold_stats(d, blocks, folds, model_cols(d, fixed));
  const auto cols0 = model_cols(d, fixed);
  const Eigen::Index p = base[0].G.rows();
  std::vector<double> best(static_cast<std::size_t>(folds), std::numeric_limits<double>::infinity());
  std::vector<std::size_t> best_s(static_cast<std::size_t>(folds), 0);
  m.for_each_setting(d, [&](std::size_t s, const Columns& cand) {
    const auto nc = static_cast<Eigen::Index>(cand[0].size());
    std::vector<FoldStats> fs = base;
    for (auto& f : fs) {
      f.G.conservativeResize(p + nc, p + nc);
      f.h.conservativeResize(p + nc);
      f.G.rightCols(nc).setZero();
      f.G.bottomRows(nc).setZero();
      f.h.tail(nc).setZero();
    }
    for (const auto& b : blocks) {
      const auto c = cols0(b.seg);
      const auto& k = cand[b.seg];
      const auto& y = d.segments[b.seg].y;
      auto& f = fs[static_cast<std::size_t>(b.fold)];
      for (Eigen::Index i = 0; i < nc; ++i) {
        const auto& ki = k[static_cast<std::size_t>(i)];
        for (Eigen::Index j = 0; j < p; ++j) {
          const double v = dot(ki, *c[static_cast<std::size_t>(j)], b.begin, b.end);
          f.G(p + i, j) += v;
          f.G(j, p + i) += v;
        }
        for (Eigen::Index j = 0; j <= i; ++j) {
          const double v = dot(ki, k[static_cast<std::size_t>(j)], b.begin, b.end);
          f.G(p + i, p + j) += v;
          if (j != i) f.G(p + j, p + i) += v;
        }
        f.h(p + i) += dot(ki, y, b.begin, b.end);
      }
    }
    for (int k = 0; k < folds; ++k) {
      const auto tr = training(fs, k);
      const Eigen::VectorXd th = solve_scaled(tr.G, tr.h);
      const double sse = tr.yy - 2.0 * th.dot(tr.h) + th.dot(tr.G * th);
      if (sse < best[static_cast<std::size_t>(k)]) {
        best[static_cast<std::size_t>(k)] = sse;
        best_s[static_cast<std::size_t>(k)] = s;
      }
    }
  });
  return best_s;
}

// Held-out prediction of the target, [segment][sample] (NaN outside the
// folds): fold k predicted by the model with extras[k] fitted on the other folds.
std::vector<std::vector<double>> heldout_prediction(const Dataset& d, const std::vector<PredBlock>& blocks, int folds,
                                                    const std::vector<std::vector<const Columns*>>& extras) {
  std::vector<std::vector<double>> out(d.segments.size());
  for (std::size_t s = 0; s < d.segments.size(); ++s)
    out[s].assign(d.segments[s].y.size(), std::numeric_limits<double>::quiet_NaN());
  for (int k = 0; k < folds; ++k) {
    const auto cols = model_cols(d, extras[static_cast<std::size_t>(k)]);
    const auto tr = training(fold_stats(d, blocks, folds, cols), k);
    const Eigen::VectorXd th = solve_scaled(tr.G, tr.h);
    for (const auto& b : blocks) {
      if (b.fold != k) continue;
      const auto c = cols(b.seg);
      for (std::size_t i = b.begin; i < b.end; ++i) {
        double v = 0.0;
        for (std::size_t j = 0; j < c.size(); ++j) v += th(static_cast<Eigen::Index>(j)) * (*c[j])[i];
        out[b.seg][i] = v;
      }
    }
  }
  return out;
}

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

// The JSON "traces" section (docs/diagnosis.md, "Figures (--plots)"): held-out
// predictions of the baseline and of the extended model.
//  single joint: one fold (the one of median baseline fold VAF), its first
//    <= 3 s: t_s, measured (the smoothed target the models predict), baseline, extended;
//  manipulandum: per time after onset (shared window), per axis: the mean
//    held-out residual over trials and its 95 % half-width (1.96 SD/sqrt(n)),
//    before and after; and three example trials (first, middle, last used).
nlohmann::json make_traces(const Dataset& d, const Diagnosis& res, const std::vector<std::unique_ptr<manip::diagnosis::Mechanism>>& lib,
                           const manip::diagnosis::EngineOptions& eo) {
  std::size_t history = 0;
  for (const auto& m : lib)
    if (m->not_applicable(d).empty()) history = std::max(history, m->history_samples(d));
  const auto blocks = engine_folds(d, eo, history);
  // Extended model as the engine scored it: the accepted mechanisms before
  // the last at their full-data settings, the last with its setting chosen
  // per fold on the training folds.
  const auto find = [&](const std::string& id) -> const manip::diagnosis::Mechanism& {
    for (const auto& m : lib)
      if (m->id() == id) return *m;
    throw std::logic_error("accepted mechanism " + id + " not in the library");
  };
  std::vector<Columns> fixed_cols;
  fixed_cols.reserve(res.accepted.size());
  for (std::size_t a = 0; a + 1 < res.accepted.size(); ++a) fixed_cols.push_back(find(res.accepted[a]).columns(d, res.accepted_settings[a]));
  std::vector<const Columns*> fixed;
  for (const auto& c : fixed_cols) fixed.push_back(&c);
  const bool extended = res.misfit_found();
  const std::vector<std::vector<const Columns*>> none(static_cast<std::size_t>(eo.folds));
  const auto p0 = heldout_prediction(d, blocks, eo.folds, none);
  std::vector<std::vector<double>> p1 = p0;
  std::map<std::size_t, Columns> last_cols;  // per grid index chosen by some fold
  if (extended) {
    const auto& last = find(res.accepted.back());
    const auto settings = per_fold_settings(d, blocks, eo.folds, fixed, last);
    const auto grid = last.grid(d);
    for (const auto s : settings)
      if (!last_cols.count(s)) last_cols.emplace(s, last.columns(d, grid[s]));
    std::vector<std::vector<const Columns*>> ext(static_cast<std::size_t>(eo.folds), fixed);
    for (int k = 0; k < eo.folds; ++k) ext[static_cast<std::size_t>(k)].push_back(&last_cols.at(settings[static_cast<std::size_t>(k)]));
    p1 = heldout_prediction(d, blocks, eo.folds, ext);
  }
  // The replicated folds must be the engine's: the fold VAFs recomputed from
  // these predictions equal the report's (else the traces are flagged and a
  // warning printed; tests check the flag).
  const auto fold_vaf = [&](const std::vector<std::vector<double>>& pred) {
    std::vector<double> v;
    for (int k = 0; k < eo.folds; ++k) {
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
  if (!matches) std::cerr << "diagnose_model: warning: the traces' held-out predictions do not reproduce the engine's fold VAFs\n";
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
  const std::size_t k0 = history;
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

// --plots DIR: refused before any input is read when it exists and is not
// empty (unless --force) or is not a directory (as estimate_impedance).
void check_plots_dir(const std::string& dir, bool force) {
  std::error_code e;
  if (fs::exists(dir, e) && !fs::is_directory(dir, e)) throw manip::OutputError("--plots " + dir + ": exists and is not a directory");
  if (!force && fs::is_directory(dir, e) && !fs::is_empty(dir, e))
    throw manip::OutputError("--plots " + dir + ": exists and is not empty (pass --force to overwrite its files); nothing was read");
}

// The figures: the report JSON (with traces) into a temporary directory, then
// python -m manipplot.diagnosis through the estimator's render mechanism
// (files moved into DIR only when all were drawn; an existing file is
// replaced only with --force).
void draw_plots(const nlohmann::json& j, const std::string& dir, bool force) {
  std::error_code e;
  std::mt19937_64 rng(std::random_device{}());
  const fs::path tmp = fs::temp_directory_path(e) / ("diagnose_model_" + std::to_string(rng() % 1000000000));
  fs::create_directories(tmp, e);
  if (e) throw manip::OutputError(tmp.string() + ": cannot create a temporary directory (" + e.message() + ")");
  struct Cleanup {
    fs::path p;
    ~Cleanup() {
      std::error_code x;
      fs::remove_all(p, x);
    }
  } cleanup{tmp};
  const std::string results = (tmp / "diagnosis.json").string();
  manip::write_file_atomically(results, j.dump(1) + "\n", true);
  const auto r = manip::estimation::render_module_into("manipplot.diagnosis", {results}, "png,pdf", dir, force);
  for (const auto& n : r.notes) std::cerr << "diagnose_model: " << n << "\n";
  if (r.manipplot_exit != 0) throw manip::OutputError("--plots " + dir + ": some figures were not drawn (see above)");
}

int run(int argc, char** argv) {
  using namespace manip;
  namespace cli = manip::cli;
  CLI::App app{"diagnose_model " + std::string(manip::kVersion) +
                   ": show what the model gets wrong on measured data, name the cause, extend the model and measure "
                   "the gain (docs/diagnosis.md)",
               "diagnose_model"};
  app.footer(kExitNotes);
  std::string single_joint, json_out, plots_dir;
  std::vector<std::string> logs;
  cli::Common c;
  cli::add_version(app, "diagnose_model");
  diagnosis::SingleJointOptions sj;
  diagnosis::EngineOptions eo;
  std::string sign = "auto";
  double inertia = -1.0;
  app.add_option("--single-joint", single_joint, "single-joint position-perturbation record (CSV: docs/diagnosis.md)");
  app.add_option("logs", logs, "manipulandum session logs (.lcm) of manip_rt or manip_sim; several logs are pooled only if their configurations agree");
  bool no_pem = false;
  int poly_order = 1;
  bool time_varying = false;
  app.add_flag("--time-varying", time_varying, "manipulandum: add the time-varying-stiffness mechanism to the library (off by default: confounded with inertia terms in a 150 ms window)");
  app.add_option("--poly-order", poly_order, "manipulandum: per-trial nuisance polynomial projected out (-1 none; default 1)")->check(CLI::Range(-1, 8));
  double t_est = 0.15;
  app.add_flag("--no-default-method", no_pem, "manipulandum: do not fit the estimator's default method (pem) for comparison");
  app.add_option("--t-est", t_est, "manipulandum: estimation window after onset (s), as estimate_impedance")->check(CLI::Range(0.05, 1.0));
  app.add_option("--json", json_out, "write the report as JSON to this file (an existing file is kept unless --force)");
  app.add_option("--plots", plots_dir,
                 "draw the figures (PNG + PDF; python -m manipplot.diagnosis, docs/diagnosis.md) into DIR, with diagnosis.json "
                 "(a non-empty DIR is refused unless --force)");
  cli::add_force(app, c.force);
  cli::add_quiet(app, c.quiet)->description("no progress on stderr (only warnings and errors)");
  app.add_option("--torque-sign", sign, "auto (K > 0 decides), +1 or -1")->check(CLI::IsMember({"auto", "+1", "-1", "1"}));
  app.add_option("--inertia", inertia, "fix the inertia to this value (kg m^2); enables the wrong-inertia mechanism")->check(CLI::NonNegativeNumber);
  app.add_option("--cutoff", sj.cutoff_hz, "Savitzky-Golay -3 dB cut-off (Hz)")->check(CLI::PositiveNumber);
  app.add_option("--folds", eo.folds, "cross-validation folds")->check(CLI::Range(3, 100));
  app.add_option("--bootstrap", eo.bootstrap, "block-bootstrap replicates")->check(CLI::Range(20, 100000));
  app.add_option("--alpha", eo.alpha, "family-wise significance level per greedy round")->check(CLI::Range(1e-6, 0.5));
  cli::set_exit_codes(app, kExitCodes);
  if (const auto rc = cli::parse(app, argc, argv)) return *rc;
  if (single_joint.empty() && logs.empty()) {
    std::cerr << "diagnose_model: give LOG.lcm [LOG...] or --single-joint FILE.csv; see --help\n";
    return ec::kUsage;
  }
  if (!logs.empty() && !single_joint.empty()) {
    std::cerr << "diagnose_model: give either session logs or --single-joint FILE.csv, not both\n";
    return ec::kUsage;
  }
  if (!c.quiet) eo.progress = [](const std::string& s) { std::cerr << "diagnose_model: " << s << "\n"; };
  // Refused before any input is read (exists without --force, directory not
  // writable); written to a temporary beside it and renamed when complete, so
  // a failed run leaves neither a truncated file nor a temporary.
  std::optional<AtomicOutput> json_file;
  if (!json_out.empty()) json_file.emplace(json_out, c.force);
  if (!plots_dir.empty()) check_plots_dir(plots_dir, c.force);
  const bool want_json = json_file.has_value() || !plots_dir.empty();
  const auto write_json = [&](const nlohmann::json& j) {
    const std::string text = j.dump(2) + "\n";
    if (std::fputs(text.c_str(), json_file->stream()) < 0) throw OutputError(json_out + ": write failed");
    json_file->commit();
  };
  if (!logs.empty()) {
    std::vector<diagnosis::CollectedSession> sessions;
    for (const auto& l : logs) {
      if (eo.progress) eo.progress("reading " + l);
      sessions.push_back(diagnosis::collect_log(l));
    }
    diagnosis::PlanarOptions po;
    po.estimator.pipeline.t_est_s = t_est;
    po.pem_baseline = !no_pem;
    po.nuisance_order = poly_order;
    if (eo.progress) eo.progress("isolating the variational signals (eq. 21)" + std::string(no_pem ? "" : " and fitting the default method"));
    auto prep = diagnosis::prepare_planar(sessions, po, eo.folds);
    const auto lib = diagnosis::planar_library(po.nuisance_order, time_varying);
    eo.require_plausible = true;
    eo.rank_by_t = true;
    eo.prefer_simpler = true;
    const auto res = diagnosis::diagnose(prep.data, lib, eo);
    if (res.misfit_found() && po.pem_baseline) {
      if (eo.progress) eo.progress("refitting the default method with the extension");
      const auto corr = diagnosis::extension_correction(prep.data, res, lib);
      prep.pem_extended = diagnosis::fit_default_method(prep, &corr);
      prep.refined = diagnosis::refine_with_default_method(prep, res, lib, eo.progress);
    }
    diagnosis::ReportContext ctx;
    ctx.front_end = "manipulandum session, variational signals of eq. 21";
    char buf[400];
    std::snprintf(buf, sizeof buf,
                  "%zu perturbed trials, window [0, %.3g] s after onset; estimator pipeline (SG jerk window %d, high-pass %.3g Hz); "
                  "two equations (x1, x2) per sample; truth channels not read",
                  prep.data.planar.size(), prep.t_est_s, prep.sg_window, po.estimator.pipeline.hp_cutoff_hz);
    ctx.preprocessing = buf;
    ctx.baseline_equation = "Δu_ext - M_BSP Δẍ = D Δẋ + K Δx (eq. 14 with eq. 21's Δu_ext; D full, K symmetric, M_BSP eq. 16 fixed)";
    ctx.cv_units = "trials (both axes of a trial in the same fold; bootstrap resamples trials)";
    ctx.target_word = "target";
    const auto pr = diagnosis::planar_report(prep, res, lib);
    ctx.extra_text = pr.text;
    std::cout << diagnosis::text_report(res, ctx);
    if (want_json) {
      auto j = diagnosis::json_report(res, ctx);
      j["manipulandum"] = pr.json;
      j["traces"] = make_traces(prep.data, res, lib, eo);
      if (json_file) write_json(j);
      if (!plots_dir.empty()) draw_plots(j, plots_dir, c.force);
    }
    return ec::kOk;
  }
  sj.torque_sign = sign == "auto" ? 0 : (sign == "-1" ? -1 : 1);
  if (inertia >= 0) {
    sj.inertia_fixed = true;
    sj.fixed_inertia_kgm2 = inertia;
  }
  const auto rec = diagnosis::read_single_joint_csv(single_joint);
  const auto prep = diagnosis::prepare_single_joint(rec, sj);
  const auto lib = diagnosis::standard_library();
  const auto res = diagnosis::diagnose(prep.data, lib, eo);
  diagnosis::ReportContext ctx;
  ctx.front_end = "single-joint CSV, position in, torque out";
  char buf[320];
  std::snprintf(buf, sizeof buf,
                "%zu samples at %.6g s; Savitzky-Golay order %d, window %d (-3 dB at %.1f Hz) on position and torque; torque sign %+d%s",
                rec.pos_rad.size(), rec.dt_s, sj.polyorder, prep.window, prep.cutoff_hz, prep.torque_sign,
                prep.sign_flipped_automatically ? " (flipped: the record stores the reaction torque, baseline K was negative)" : "");
  ctx.preprocessing = buf;
  std::cout << diagnosis::text_report(res, ctx);
  if (want_json) {
    auto j = diagnosis::json_report(res, ctx);
    j["traces"] = make_traces(prep.data, res, lib, eo);
    if (json_file) write_json(j);
    if (!plots_dir.empty()) draw_plots(j, plots_dir, c.force);
  }
  return ec::kOk;
}

}  // namespace

int main(int argc, char** argv) { return manip::cli::run_main("diagnose_model", run, argc, argv); }
