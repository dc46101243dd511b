#include "manip/diagnosis/report.hpp"

#include <cmath>
#include <cstdio>
#include <sstream>

namespace manip::diagnosis {
namespace {
std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}
}  // namespace

std::string g4(double v) { return fmt("%.4g", v); }

namespace {

std::string interval(const Interval& i) { return g4(i.value) + " [" + g4(i.lo) + ", " + g4(i.hi) + "]"; }

nlohmann::json jint(const Interval& i) { return {{"value", i.value}, {"ci95", {i.lo, i.hi}}}; }

nlohmann::json jsig(const Signatures& s) {
  nlohmann::json x = nlohmann::json::array();
  for (const auto& c : s.xcorr)
    x.push_back({{"regressor", c.regressor}, {"rho", c.rho}, {"lag_s", c.lag_s}, {"bound95", c.bound}, {"significant", c.significant}});
  return {{"resid_rms", s.resid_rms},
          {"decimation", s.decimation},
          {"skewness", s.skewness},
          {"skewness_se", s.skewness_se},
          {"excess_kurtosis", s.excess_kurtosis},
          {"kurtosis_se", s.kurtosis_se},
          {"ljung_box", {{"q", s.ljung_box.q}, {"lags", s.ljung_box.lags}, {"p", s.ljung_box.p_value}}},
          {"xcorr", x}};
}

void sig_text(std::ostringstream& o, const Signatures& s) {
  o << "  residual RMS " << g4(s.resid_rms) << "; on every " << s.decimation << "th sample: skewness " << fmt("%.3f", s.skewness)
    << " (SE " << fmt("%.3f", s.skewness_se) << " if Gaussian), excess kurtosis " << fmt("%.3f", s.excess_kurtosis) << " (SE "
    << fmt("%.3f", s.kurtosis_se) << ")\n";
  o << "  whiteness: Ljung-Box Q(" << s.ljung_box.lags << ") = " << fmt("%.1f", s.ljung_box.q) << ", p = " << fmt("%.3g", s.ljung_box.p_value)
    << (s.ljung_box.p_value < 0.05 ? "  (residual not white)" : "  (white at 5 %)") << "\n";
  o << "  cross-correlation of the residual with candidate regressors (largest over lags 0-100 ms where delayed):\n";
  for (const auto& c : s.xcorr)
    o << "    " << c.regressor << std::string(c.regressor.size() < 32 ? 32 - c.regressor.size() : 1, ' ') << "rho "
      << fmt("%+.3f", c.rho) << (c.lag_s > 0 ? " at " + fmt("%.0f", c.lag_s * 1e3) + " ms" : std::string("        ")) << "  bound "
      << fmt("%.3f", c.bound) << (c.significant ? "  SIGNIFICANT" : "") << "\n";
}

}  // namespace

nlohmann::json param_json(const ParamEstimate& p) {
  nlohmann::json j = {{"name", p.name}, {"unit", p.unit}, {"value", p.est.value}, {"ci95", {p.est.lo, p.est.hi}}};
  if (p.lo_open || p.hi_open) j["ci95_open"] = {p.lo_open, p.hi_open};
  if (p.has_bounds) {
    j["plausible"] = {p.plausible_lo, p.plausible_hi};
    j["within_plausible"] = p.plausible();
    if (p.shape) j["at_edge_of_search"] = p.at_edge();
  }
  return j;
}

std::string text_report(const Diagnosis& d, const ReportContext& ctx) {
  std::ostringstream o;
  o << "diagnose_model: " << d.source << " (" << ctx.front_end << ")\n";
  if (!ctx.preprocessing.empty()) o << "  " << ctx.preprocessing << "\n";
  if (ctx.cv_units.empty())
    o << "  " << d.n_used << " samples used (" << fmt("%.1f", d.duration_s) << " s), " << d.folds << "-fold cross-validation over contiguous blocks, guard "
      << fmt("%.2f", d.guard_s) << " s; bootstrap over " << d.blocks << " blocks; intervals are 95 %\n\n";
  else
    o << "  " << d.n_used << " samples used, " << d.folds << "-fold cross-validation over " << ctx.cv_units << "; intervals are 95 %\n\n";
  o << "Baseline: " << ctx.baseline_equation << "\n";
  for (const auto& p : d.baseline_params) o << "  " << p.name << " = " << interval(p.est) << " " << p.unit << "\n";
  o << "  held-out VAF " << interval(d.baseline_heldout.vaf) << ", NRMSE " << interval(d.baseline_heldout.nrmse) << "\n";
  o << "  held-out VAF per fold (time order):";
  for (double v : d.baseline_heldout.fold_vaf) o << " " << fmt("%.3f", v);
  o << "\n\nMisfit signatures (baseline residual):\n";
  sig_text(o, d.before);
  o << "\nMechanism search (held-out gain = relative reduction of the held-out squared error; one-sided t over folds, Holm-adjusted):\n";
  for (std::size_t r = 0; r < d.rounds.size(); ++r) {
    o << " round " << r + 1 << ":\n";
    for (std::size_t i = 0; i < d.rounds[r].candidates.size(); ++i) {
      const auto& c = d.rounds[r].candidates[i];
      o << "   " << c.id << std::string(c.id.size() < 22 ? 22 - c.id.size() : 1, ' ');
      if (!c.not_applicable.empty()) {
        o << "not applicable: " << c.not_applicable << "\n";
        continue;
      }
      o << "gain " << fmt("%+.4f", c.test.mean) << " +- " << fmt("%.4f", c.test.se) << "  p_holm " << fmt("%.2g", c.p_holm)
        << (static_cast<int>(i) == d.rounds[r].accepted ? "  <- ACCEPTED"
                                                        : (c.significant ? (c.implausible ? "  significant, IMPLAUSIBLE parameters (not accepted)" : "  significant")
                                                                         : (c.implausible ? "  implausible parameters" : "")))
        << "  (";
      for (std::size_t k = 0; k < c.params.size(); ++k) o << (k ? ", " : "") << c.params[k].name << " " << g4(c.params[k].est.value);
      o << ")\n";
    }
  }
  if (!d.rounds.empty()) {
    o << "\nDetection limits of this session (round 1, against the baseline): per gain, its estimate +- cluster-robust SE and\n"
         "the smallest |gain| detected with 90 % power at the round's level (in-sample Wald; the cross-validated search needs more):\n";
    for (const auto& c : d.rounds.front().candidates) {
      if (!c.not_applicable.empty() || c.gain_mde.empty()) continue;
      o << "   " << c.id << std::string(c.id.size() < 22 ? 22 - c.id.size() : 1, ' ');
      const std::size_t ns = c.params.size() - c.gain_se.size();
      for (std::size_t k = 0; k < c.gain_se.size(); ++k) {
        const auto& pp = c.params[ns + k];
        o << (k ? "; " : "") << pp.name << " " << g4(pp.est.value) << " +- " << g4(c.gain_se[k]) << ", limit " << g4(c.gain_mde[k]) << " " << pp.unit;
      }
      o << "  (" << c.clusters << " units)\n";
    }
  }
  o << "\n";
  // Candidates of the last round that improved the held-out prediction
  // significantly with unphysical parameters (EngineOptions::require_physical,
  // require_plausible): a misfit, but none the library can name.
  std::string unphysical;
  if (!d.rounds.empty())
    for (const auto& c : d.rounds.back().candidates)
      if (c.significant && c.implausible) unphysical += (unphysical.empty() ? "" : ", ") + c.id;
  if (!d.misfit_found() && unphysical.empty()) {
    o << "Result: no significant misfit: no mechanism of the library improves the held-out prediction significantly.\n";
  } else if (!d.misfit_found()) {
    o << "Result: nothing named: " << unphysical
      << " improve(s) the held-out prediction significantly, but only with parameters the library calls unphysical "
         "(IMPLAUSIBLE above): a misfit outside the library's mechanisms.\n";
  } else {
    o << "Result: named cause(s), in the order added:\n";
    for (std::size_t a = 0; a < d.accepted.size(); ++a) {
      for (const auto& r : d.rounds)
        if (r.accepted >= 0 && r.candidates[static_cast<std::size_t>(r.accepted)].id == d.accepted[a]) {
          const auto& c = r.candidates[static_cast<std::size_t>(r.accepted)];
          o << "  " << a + 1 << ". " << c.title << "\n     signature: " << c.signature << "\n";
        }
    }
    if (!unphysical.empty())
      o << "  then not named: " << unphysical << " (a significant held-out gain, but only with unphysical parameters: IMPLAUSIBLE above)\n";
    o << "  held-out VAF " << interval(d.baseline_heldout.vaf) << " -> " << interval(d.final_heldout.vaf) << "\n";
    o << "  held-out NRMSE " << interval(d.baseline_heldout.nrmse) << " -> " << interval(d.final_heldout.nrmse) << "\n";
    o << "  held-out gain (1 - SSE_after/SSE_before) " << interval(d.heldout_gain) << "\n";
    o << "  extended model, parameters (block bootstrap):\n";
    for (const auto& p : d.final_params)
      o << "    " << p.name << " = " << interval(p.est) << " " << p.unit << (p.plausible() ? "" : "  OUTSIDE plausible range")
        << (p.at_edge() ? "  AT THE EDGE of the search range (" + g4(p.plausible_lo) + "-" + g4(p.plausible_hi) + ")" : "") << "\n";
    o << "  share of the " << ctx.target_word << " (RMS of the term / RMS of the measured " << ctx.target_word << " " << g4(d.target_rms) << "):\n";
    for (std::size_t a = 0; a < d.accepted.size() && a < d.contribution_rms.size(); ++a)
      o << "    " << d.accepted[a] << ": RMS " << g4(d.contribution_rms[a]) << " (" << fmt("%.1f", 100.0 * d.contribution_rms[a] / d.target_rms)
        << " %)\n";
    if (d.find_baseline("K")) o << "  intrinsic impedance before -> after modelling the cause:\n";
    for (const char* n : {"I", "B", "K"}) {
      const auto* b = d.find_baseline(n);
      const auto* f = d.find_final(n);
      if (b && f)
        o << "    " << n << ": " << interval(b->est) << " -> " << interval(f->est) << " " << b->unit << " ("
          << fmt("%+.1f", 100.0 * (f->est.value - b->est.value) / std::fabs(b->est.value)) << " %)\n";
    }
    for (const auto& dp : d.derived_params) {
      const auto* b = d.find_baseline(dp.base);
      o << "    " << dp.param.name << " = " << dp.meaning << ":\n      ";
      if (b) o << interval(b->est) << " (baseline " << b->name << ") -> ";
      o << interval(dp.param.est) << " " << dp.param.unit;
      if (b) o << " (" << fmt("%+.1f", 100.0 * (dp.param.est.value - b->est.value) / std::fabs(b->est.value)) << " %)";
      o << "\n";
    }
    o << "\nWhat remains (residual of the extended model):\n";
    sig_text(o, d.after);
  }
  o << ctx.extra_text;
  o << "\ndiagnosis took " << fmt("%.2f", d.seconds) << " s\n";
  return o.str();
}

nlohmann::json json_report(const Diagnosis& d, const ReportContext& ctx) {
  nlohmann::json j;
  j["source"] = d.source;
  j["front_end"] = ctx.front_end;
  j["preprocessing"] = ctx.preprocessing;
  j["samples_used"] = d.n_used;
  j["duration_s"] = d.duration_s;
  j["folds"] = d.folds;
  j["blocks"] = d.blocks;
  j["guard_s"] = d.guard_s;
  for (const auto& p : d.baseline_params) j["baseline"]["params"].push_back(param_json(p));
  j["baseline"]["heldout_vaf"] = jint(d.baseline_heldout.vaf);
  j["baseline"]["heldout_nrmse"] = jint(d.baseline_heldout.nrmse);
  j["baseline"]["fold_vaf"] = d.baseline_heldout.fold_vaf;
  j["signatures_before"] = jsig(d.before);
  j["signatures_after"] = jsig(d.after);
  j["rounds"] = nlohmann::json::array();
  for (const auto& r : d.rounds) {
    nlohmann::json jr;
    jr["accepted"] = r.accepted >= 0 ? nlohmann::json(r.candidates[static_cast<std::size_t>(r.accepted)].id) : nlohmann::json(nullptr);
    for (const auto& c : r.candidates) {
      nlohmann::json jc = {{"id", c.id}, {"title", c.title}, {"signature", c.signature}};
      if (!c.not_applicable.empty()) {
        jc["not_applicable"] = c.not_applicable;
      } else {
        jc["fold_gain"] = c.fold_gain;
        if (!c.fold_main.empty()) jc["fold_main_param"] = c.fold_main;
        jc["mean_gain"] = c.test.mean;
        jc["se"] = c.test.se;
        jc["t"] = c.test.t;
        jc["p"] = c.test.p_value;
        jc["p_holm"] = c.p_holm;
        jc["significant"] = c.significant;
        jc["implausible"] = c.implausible;
        for (const auto& p : c.params) jc["params"][p.name] = p.est.value;
        const std::size_t ns = c.params.size() - c.gain_se.size();
        for (std::size_t k = 0; k < c.gain_se.size(); ++k) {
          jc["detection"][c.params[ns + k].name] = {{"se", c.gain_se[k]}, {"limit_90", k < c.gain_mde.size() ? c.gain_mde[k] : 0.0}};
        }
        jc["detection_units"] = c.clusters;
      }
      jr["candidates"].push_back(jc);
    }
    j["rounds"].push_back(jr);
  }
  j["misfit"] = d.misfit_found();
  j["significant_unphysical"] = nlohmann::json::array();
  if (!d.rounds.empty())
    for (const auto& c : d.rounds.back().candidates)
      if (c.significant && c.implausible) j["significant_unphysical"].push_back(c.id);
  j["accepted"] = d.accepted;
  j["final"]["heldout_vaf"] = jint(d.final_heldout.vaf);
  j["final"]["heldout_nrmse"] = jint(d.final_heldout.nrmse);
  j["final"]["heldout_gain"] = jint(d.heldout_gain);
  j["final"]["fold_vaf"] = d.final_heldout.fold_vaf;
  j["final"]["target_rms"] = d.target_rms;
  j["final"]["contribution_rms"] = d.contribution_rms;
  j["final"]["params"] = nlohmann::json::array();
  for (const auto& p : d.final_params) j["final"]["params"].push_back(param_json(p));
  j["final"]["derived"] = nlohmann::json::array();
  for (const auto& dp : d.derived_params) {
    auto e = param_json(dp.param);
    e["base"] = dp.base;
    e["meaning"] = dp.meaning;
    j["final"]["derived"].push_back(e);
  }
  j["seconds"] = d.seconds;
  return j;
}

}  // namespace manip::diagnosis
