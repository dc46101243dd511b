#include "manip/estimation/report/json.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

#include "manip/common/errors.hpp"
#include "manip/estimation/methods/registry.hpp"
#include "manip/estimation/report/format.hpp"

namespace manip::estimation {

using report_detail::fmt;
using report_detail::mat;
using report_detail::create_output_dir;
namespace {

nlohmann::json disturbance_json(const DisturbanceModel& d) {
  return {{"structure", d.box_jenkins ? "box-jenkins" : "armax"},
          {"motor_noise_std_n", d.motor_noise_n},
          {"motor_noise_tau_s", d.motor_tau_s},
          {"drive_psd_n2ps3", d.drive_psd},
          {"measurement_noise_std_m", d.meas_std_m},
          {"D_v_Nspm", mat(d.d_nspm)},
          {"K_v_Npm", mat(d.k_npm)},
          {"neg_log_likelihood", d.neg_log_likelihood}};
}

nlohmann::json estimate_json(const ImpedanceEstimate& e) {
  nlohmann::json j = {{"M_kg", mat(e.m_kg)},
          {"M_estimated", e.m_estimated},
          {"D_Nspm", mat(e.d_nspm)},
          {"K_Npm", mat(e.k_npm)},
          {"D_se", mat(e.d_se)},
          {"K_se", mat(e.k_se)},
          {"M_se", mat(e.m_se)},
          {"se_kind", e.se_kind},
          {"ci_factor", e.ci_factor},
          {"residual_rms", e.residual_rms},
          {"vaf", e.vaf},
          {"condition", e.condition},
          {"n_samples", e.n_samples},
          {"n_params", e.n_params},
          {"n_trials", e.n_trials},
          {"iterations", e.iterations},
          {"identifiable", e.identifiable},
          {"flag", e.flag}};
  if (e.disturbance) j["disturbance"] = disturbance_json(*e.disturbance);
  return j;
}

nlohmann::json summary_json(const Summary& s) {
  nlohmann::json j = {{"method", s.method}, {"group", s.group.label()}, {"angle_deg", s.group.is_angle() ? nlohmann::json(s.group.angle_deg) : nlohmann::json(nullptr)},       {"kind", s.kind},           {"n_trials", s.n_trials},
          {"D_Nspm", mat(s.d_nspm)}, {"K_Npm", mat(s.k_npm)}, {"D_spread", mat(s.d_spread)},
          {"K_spread", mat(s.k_spread)}, {"D_ci95_lo", mat(s.d_lo)}, {"D_ci95_hi", mat(s.d_hi)},
          {"K_ci95_lo", mat(s.k_lo)}, {"K_ci95_hi", mat(s.k_hi)}, {"M_kg", mat(s.m_kg)},
          {"identifiable", s.identifiable}, {"flag", s.flag}, {"n_flagged_trials", s.n_flagged_trials}};
  if (s.disturbance) j["disturbance"] = disturbance_json(*s.disturbance);
  if (s.directional) {
    const auto& d = *s.directional;
    auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
    j["direction_u"] = {d.u.x(), d.u.y()};
    j["D_dir_Nspm"] = num(d.d_nspm);
    j["K_dir_Npm"] = num(d.k_npm);
    j["D_dir_ci95_lo"] = num(d.d_lo);
    j["D_dir_ci95_hi"] = num(d.d_hi);
    j["K_dir_ci95_lo"] = num(d.k_lo);
    j["K_dir_ci95_hi"] = num(d.k_hi);
    j["D_dir_std"] = num(d.d_std);
    j["K_dir_std"] = num(d.k_std);
    j["dir_n_trials"] = d.n_trials;
    // One trial gives no interval: say so rather than plot a bare point as a result.
    j["dir_identifiable"] = d.n_trials >= 2;
    j["dir_flag"] = d.n_trials >= 2 ? "" : "one trial at this angle: no interval";
    j["D_dir_trials_Nspm"] = d.d_trials;
    j["K_dir_trials_Npm"] = d.k_trials;
    if (std::isfinite(d.k_true)) {
      j["D_dir_true_Nspm"] = d.d_true;
      j["K_dir_true_Npm"] = d.k_true;
    }
    j["dir_method"] = "1-D least squares along the push per trial, mean and Student-t 95 % interval over trials";
  }
  return j;
}

}  // namespace

nlohmann::json to_json(const Report& r, const std::string& log_name) {
  nlohmann::json j;
  j["log"] = log_name;
  j["session"] = {{"source", r.info.source},
                  {"software_version", r.info.software_version},
                  {"participant_id", r.info.participant_id},
                  {"session_id", r.info.session_id},
                  {"schema_version", r.info.schema_version},
                  {"sample_rate_hz", r.info.sample_rate_hz}};
  j["settings"] = settings_to_json(r.settings);
  j["cutoff_used_hz"] = r.cutoff_used_hz;
  j["sg_window"] = r.sg_window;
  j["counts"] = {{"trials", r.n_trials}, {"perturbed", r.n_perturbed}, {"used", r.n_used}};
  j["position_used"] = to_string(r.position_used);
  if (r.position_used == PositionSource::reference || r.position_used == PositionSource::tracked)
    j["reference_alignment"] = {{"shift0_trials", r.n_reference_shift0},
                                {"shift1_trials", r.n_reference_shift1},
                                {"encoder_fallback_trials", r.reference_fallback_trials}};
  auto& summ = j["summaries"] = nlohmann::json::array();
  for (const auto& s : r.summaries) summ.push_back(summary_json(s));
  // Session summary per method, as promised in docs/estimator.md.
  nlohmann::json by_method = nlohmann::json::object();
  for (const auto& s : r.summaries)
    if (s.group.is_session())
      by_method[s.method] = {{"D_Nspm", mat(s.d_nspm)}, {"K_Npm", mat(s.k_npm)}, {"D_se", mat(s.d_spread)},
                             {"K_se", mat(s.k_spread)}, {"kind", s.kind}, {"identifiable", s.identifiable}};
  j["session_summary"] = by_method;
  auto& trials = j["trials"] = nlohmann::json::array();
  for (const auto& t : r.trials) {
    auto e = estimate_json(t.est);
    e["trial"] = t.trial;
    e["angle_deg"] = t.angle_deg;
    e["method"] = t.method;
    if (std::isfinite(t.nrmse_dx.x())) e["nrmse_dx"] = {t.nrmse_dx.x(), t.nrmse_dx.y()};
    trials.push_back(e);
  }
  j["psd"] = {{"peak_unperturbed_hz", r.psd.peak_unperturbed_hz},
              {"cutoff_auto_hz", std::isfinite(r.psd.cutoff_auto_hz) ? nlohmann::json(r.psd.cutoff_auto_hz) : nlohmann::json(nullptr)},
              {"ratio_at_1hz_db", std::isfinite(r.psd.ratio_at_1hz_db) ? nlohmann::json(r.psd.ratio_at_1hz_db) : nlohmann::json(nullptr)},
              {"n_unperturbed", r.psd.n_unperturbed},
              {"n_perturbed", r.psd.n_perturbed}};
  // The averaged jerk PSDs up to 50 Hz (Fig. 3 without reading the log).
  {
    std::vector<double> f, pu, pp;
    for (std::size_t i = 0; i < r.psd.f_hz.size() && r.psd.f_hz[i] <= 50.0; ++i) {
      f.push_back(r.psd.f_hz[i]);
      pu.push_back(i < r.psd.p_unperturbed.size() ? r.psd.p_unperturbed[i] : 0.0);
      pp.push_back(i < r.psd.p_perturbed.size() ? r.psd.p_perturbed[i] : 0.0);
    }
    j["psd"]["f_hz"] = f;
    j["psd"]["p_unperturbed"] = pu;
    j["psd"]["p_perturbed"] = pp;
    j["psd"]["unit"] = "(m/s^3)^2/Hz";
  }
  j["default_method"] = default_method();
  // "truth": the intrinsic truth (per-trial messages, averaged; key kept for
  // existing readers); "truth_apparent": the session's apparent truth
  // (intrinsic + feedback within [0, t_est_s]); docs/estimator.md.
  if (r.truth.available)
    j["truth"] = {{"kind", "intrinsic"},          {"model", r.truth.model},  {"n_trials", r.truth.n_trials},
                  {"D_Nspm", mat(r.truth.d_nspm)}, {"K_Npm", mat(r.truth.k_npm)}, {"M_kg", mat(r.truth.m_kg)}};
  if (const auto& ap = r.truth.apparent)
    j["truth_apparent"] = {{"kind", "apparent"},       {"model", ap->model},          {"t_est_s", ap->t_est_s},
                           {"D_Nspm", mat(ap->d_nspm)}, {"K_Npm", mat(ap->k_npm)}, {"M_kg", mat(ap->m_kg)}};
  auto& iss = j["issues"] = nlohmann::json::array();
  for (const auto& i : r.issues) iss.push_back({{"trial", i.trial}, {"reason", i.reason}});
  j["warnings"] = r.warnings;
  return j;
}

}  // namespace manip::estimation
