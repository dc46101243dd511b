#include "manip/estimation/report.hpp"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>
#include <stdexcept>

namespace manip::estimation {
namespace {

nlohmann::json mat(const Mat2& m) {  // row-major 2x2
  auto f = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return nlohmann::json::array({f(m(0, 0)), f(m(0, 1)), f(m(1, 0)), f(m(1, 1))});
}

std::string fmt(double v, int prec = 2) {
  if (!std::isfinite(v)) return "n/a";
  std::ostringstream o;
  o << std::fixed << std::setprecision(prec) << v;
  return o.str();
}

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
  nlohmann::json j = {{"method", s.method}, {"group", s.group},       {"kind", s.kind},           {"n_trials", s.n_trials},
          {"D_Nspm", mat(s.d_nspm)}, {"K_Npm", mat(s.k_npm)}, {"D_spread", mat(s.d_spread)},
          {"K_spread", mat(s.k_spread)}, {"D_ci95_lo", mat(s.d_lo)}, {"D_ci95_hi", mat(s.d_hi)},
          {"K_ci95_lo", mat(s.k_lo)}, {"K_ci95_hi", mat(s.k_hi)}, {"M_kg", mat(s.m_kg)},
          {"identifiable", s.identifiable}, {"flag", s.flag}, {"n_flagged_trials", s.n_flagged_trials}};
  if (s.disturbance) j["disturbance"] = disturbance_json(*s.disturbance);
  return j;
}

// ---- minimal SVG line plots (no plotting dependency in the C++ tool) ------
struct Series {
  std::string name;
  std::vector<double> x, y;
  std::string color;
};

void svg_plot(const std::string& path, const std::string& title, const std::string& xlabel, const std::string& ylabel,
              const std::vector<Series>& series, bool logy = false, double xmax = NAN) {
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
  const double pad = 0.05 * (y1 - y0);
  y0 -= pad;
  y1 += pad;
  auto px = [&](double x) { return L + (x - x0) / (x1 - x0) * (W - L - R); };
  auto py = [&](double y) { return T + (y1 - std::clamp(y, y0, y1)) / (y1 - y0) * (H - T - B); };
  std::ofstream o(path);
  if (!o) throw std::runtime_error(path + ": cannot write plot");
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
    o << "<polyline fill='none' stroke='" << s.color << "' stroke-width='1.2' points='";
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

template <class T>
T get_as(const YAML::Node& n, const std::string& file, const std::string& key) {
  try {
    return n.as<T>();
  } catch (const std::exception&) {
    throw std::runtime_error(file + ": " + key + ": wrong type or value");
  }
}

}  // namespace

nlohmann::json settings_to_json(const EstimatorSettings& s) {
  const auto& p = s.pipeline;
  return {{"methods", s.methods},
          {"sg_order", p.sg_order},
          {"sg_cutoff_hz", p.sg_cutoff_hz},
          {"sg_window", p.sg_window},
          {"hp_order", p.hp_order},
          {"hp_cutoff_hz", p.hp_cutoff_hz},
          {"cutoff_auto", s.cutoff_auto},
          {"cutoff_auto_threshold_db", s.cutoff_auto_threshold_db},
          {"psd_nfft", s.psd_nfft},
          {"t_est_s", p.t_est_s},
          {"k_model", s.ls.k_model == StiffnessModel::symmetric ? "symmetric" : "full"},
          {"estimate_m", s.ls.estimate_m},
          {"force_source", s.ls.force == ForceSource::admittance ? "admittance" : "sensor"},
          {"oe_t_pre_s", s.oe.t_pre_s},
          {"oe_t_est_s", s.oe.t_est_s},
          {"oe_poly_order", s.oe.poly_order},
          {"oe_max_iterations", s.oe.max_iterations},
          {"oe_jackknife", s.oe.jackknife},
          {"oe_prewhiten_order", s.oe.prewhiten_order},
          {"pem_t_pre_s", s.pem.t_pre_s},
          {"pem_t_est_s", s.pem.t_est_s},
          {"pem_structure", s.pem.structure == PemStructure::box_jenkins ? "box-jenkins" : "armax"},
          {"pem_se", s.pem.se == PemSe::sandwich ? "sandwich" : (s.pem.se == PemSe::fisher ? "fisher" : "jackknife")},
          {"pem_max_iterations", s.pem.max_iterations}};
}

nlohmann::json to_json(const Report& r, const std::string& log_name) {
  nlohmann::json j;
  j["log"] = log_name;
  j["session"] = {{"source", r.info.source},
                  {"software_version", r.info.software_version},
                  {"participant_id", r.info.participant_id},
                  {"session_id", r.info.session_id},
                  {"schema_version", r.info.schema_version},
                  {"sample_rate_hz", r.info.fs_hz}};
  j["settings"] = settings_to_json(r.settings);
  j["cutoff_used_hz"] = r.cutoff_used_hz;
  j["sg_window"] = r.sg_window;
  j["counts"] = {{"trials", r.n_trials}, {"perturbed", r.n_perturbed}, {"used", r.n_used}};
  auto& summ = j["summaries"] = nlohmann::json::array();
  for (const auto& s : r.summaries) summ.push_back(summary_json(s));
  // Session summary per method, as promised in docs/estimator.md.
  nlohmann::json by_method = nlohmann::json::object();
  for (const auto& s : r.summaries)
    if (s.group == "session")
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
  if (r.truth.available)
    j["truth"] = {{"model", r.truth.model}, {"n_trials", r.truth.n_trials}, {"D_Nspm", mat(r.truth.d_nspm)},
                  {"K_Npm", mat(r.truth.k_npm)}, {"M_kg", mat(r.truth.m_kg)}};
  auto& iss = j["issues"] = nlohmann::json::array();
  for (const auto& i : r.issues) iss.push_back({{"trial", i.trial}, {"reason", i.reason}});
  j["warnings"] = r.warnings;
  return j;
}

std::string format_text(const Report& r, const std::string& log_name) {
  std::ostringstream o;
  o << "manip estimate_impedance: " << log_name << "\n";
  o << "  session " << r.info.session_id << ", participant " << r.info.participant_id << ", source " << r.info.source
    << ", " << r.info.fs_hz << " Hz\n";
  o << "  trials " << r.n_trials << ", perturbed " << r.n_perturbed << ", used " << r.n_used << "; SG window "
    << r.sg_window << ", high-pass " << fmt(r.cutoff_used_hz, 3) << " Hz"
    << (r.settings.cutoff_auto ? " (auto)" : "") << ", T_est " << r.settings.pipeline.t_est_s << " s\n";
  if (r.psd.n_unperturbed > 0)
    o << "  PSD: unperturbed peak " << fmt(r.psd.peak_unperturbed_hz, 3) << " Hz; auto cut-off "
      << fmt(r.psd.cutoff_auto_hz, 3) << " Hz (ratio > " << r.settings.cutoff_auto_threshold_db
      << " dB); perturbed/unperturbed at 1 Hz " << fmt(r.psd.ratio_at_1hz_db, 1) << " dB\n";
  for (const auto& s : r.summaries) {
    if (s.group != "session") continue;
    o << "\n  method " << s.method << ": " << s.kind << ", " << s.n_trials << " trials"
      << (s.identifiable ? "" : "  ** NOT IDENTIFIABLE: " + s.flag + " **") << "\n";
    const bool pooled = s.kind.rfind("pooled", 0) == 0;
    o << "    Damping D [Ns/m]" << std::string(22, ' ') << "Stiffness K [N/m]\n";
    for (int i = 0; i < 2; ++i) {
      std::ostringstream row;
      for (int j = 0; j < 2; ++j)
        row << std::setw(8) << fmt(s.d_nspm(i, j)) << " (" << std::setw(6) << fmt(s.d_spread(i, j)) << ") ";
      row << "   ";
      for (int j = 0; j < 2; ++j)
        row << std::setw(8) << fmt(s.k_npm(i, j)) << " (" << std::setw(6) << fmt(s.k_spread(i, j)) << ") ";
      o << "    " << row.str() << "\n";
    }
    o << "    (" << (pooled ? "estimate (SE)" : "mean (std)") << "; M_BSP at onset ~ [" << fmt(s.m_kg(0, 0)) << ", "
      << fmt(s.m_kg(0, 1)) << "; " << fmt(s.m_kg(1, 0)) << ", " << fmt(s.m_kg(1, 1)) << "] kg)\n";
    if (pooled)
      o << "    95% CI: D11 [" << fmt(s.d_lo(0, 0)) << ", " << fmt(s.d_hi(0, 0)) << "], K11 [" << fmt(s.k_lo(0, 0))
        << ", " << fmt(s.k_hi(0, 0)) << "], K22 [" << fmt(s.k_lo(1, 1)) << ", " << fmt(s.k_hi(1, 1)) << "]\n";
    if (s.disturbance)
      o << "    person's own motion (" << (s.disturbance->box_jenkins ? "box-jenkins" : "armax") << "): motor noise " << fmt(s.disturbance->motor_noise_n, 3)
        << " N std, tau " << fmt(s.disturbance->motor_tau_s * 1000, 1) << " ms; position noise "
        << fmt(s.disturbance->meas_std_m * 1e6, 2) << " um std\n";
  }
  if (r.truth.available) {
    o << "\n  ground truth (" << r.truth.model << ", mean over " << r.truth.n_trials << " trials): D = ["
      << fmt(r.truth.d_nspm(0, 0)) << ", " << fmt(r.truth.d_nspm(0, 1)) << "; " << fmt(r.truth.d_nspm(1, 0)) << ", "
      << fmt(r.truth.d_nspm(1, 1)) << "], K = [" << fmt(r.truth.k_npm(0, 0)) << ", " << fmt(r.truth.k_npm(0, 1)) << "; "
      << fmt(r.truth.k_npm(1, 0)) << ", " << fmt(r.truth.k_npm(1, 1)) << "]\n";
    for (const auto& s : r.summaries) {
      if (s.group != "session") continue;
      o << "    " << std::left << std::setw(13) << s.method << std::right << " error vs truth: D";
      for (int i = 0; i < 4; ++i) {
        const double t = r.truth.d_nspm(i / 2, i % 2);
        o << " " << fmt(100.0 * (s.d_nspm(i / 2, i % 2) - t) / std::abs(t), 1) << "%";
      }
      o << "  K";
      for (int i : {0, 1, 3}) {
        const double t = r.truth.k_npm(i / 2, i % 2);
        o << " " << fmt(100.0 * (s.k_npm(i / 2, i % 2) - t) / std::abs(t), 1) << "%";
      }
      o << "\n";
    }
  }
  if (!r.trials.empty()) {
    o << "\n  per trial:\n    method    trial angle    D11     D12     D21     D22     K11     K12     K22   VAF  flag\n";
    for (const auto& t : r.trials) {
      o << "    " << std::left << std::setw(9) << t.method << std::right << std::setw(6) << t.trial << std::setw(6)
        << fmt(t.angle_deg, 0);
      for (int i = 0; i < 4; ++i) o << std::setw(8) << fmt(t.est.d_nspm(i / 2, i % 2), 1);
      o << std::setw(8) << fmt(t.est.k_npm(0, 0), 0) << std::setw(8) << fmt(t.est.k_npm(0, 1), 0) << std::setw(8)
        << fmt(t.est.k_npm(1, 1), 0) << std::setw(6) << fmt(t.est.vaf, 2) << "  " << (t.est.identifiable ? "" : "not identifiable") << "\n";
    }
  }
  for (const auto& i : r.issues) o << "  excluded: trial " << i.trial << ": " << i.reason << "\n";
  for (const auto& w : r.warnings) o << "  warning: " << w << "\n";
  return o.str();
}

void write_csv(const std::vector<std::pair<std::string, Report>>& reports, const std::string& path) {
  std::ofstream o(path);
  if (!o) throw std::runtime_error(path + ": cannot write CSV");
  o << "log,method,group,kind,trial,angle_deg,n_trials,D11,D12,D21,D22,K11,K12,K21,K22,"
       "D11_se,D12_se,D21_se,D22_se,K11_se,K12_se,K21_se,K22_se,vaf,identifiable\n";
  o << std::setprecision(10);
  auto row = [&](const std::string& log, const std::string& m, const std::string& g, const std::string& kind, int trial,
                 double ang, int n, const Mat2& d, const Mat2& k, const Mat2& dse, const Mat2& kse, double vaf, bool ok) {
    o << log << ',' << m << ',' << g << ",\"" << kind << "\"," << trial << ',' << ang << ',' << n;
    for (const Mat2* mm : {&d, &k, &dse, &kse})
      for (int i = 0; i < 4; ++i) o << ',' << (*mm)(i / 2, i % 2);
    o << ',' << vaf << ',' << (ok ? 1 : 0) << '\n';
  };
  for (const auto& [log, r] : reports) {
    for (const auto& s : r.summaries)
      row(log, s.method, s.group, s.kind, -1, NAN, s.n_trials, s.d_nspm, s.k_npm, s.d_spread, s.k_spread, NAN, s.identifiable);
    for (const auto& t : r.trials)
      row(log, t.method, "trial", "per-trial fit", t.trial, t.angle_deg, 1, t.est.d_nspm, t.est.k_npm, t.est.d_se,
          t.est.k_se, t.est.vaf, t.est.identifiable);
  }
  if (!o) throw std::runtime_error(path + ": write failed");
}

void export_signals(const Report& r, const std::string& dir) {
  std::filesystem::create_directories(dir);
  for (const auto& w : r.windows) {
    const std::string path = dir + "/trial_" + std::to_string(w.trial) + ".csv";
    std::ofstream o(path);
    if (!o) throw std::runtime_error(path + ": cannot write");
    o << std::setprecision(12);
    o << "t_s,dx1_m,dx2_m,dxd1_mps,dxd2_mps,dxdd1_mps2,dxdd2_mps2,du_ext_adm1_n,du_ext_adm2_n,du_ext_force1_n,"
         "du_ext_force2_n,u_pert1_n,u_pert2_n"
      << (w.dx_true.empty() ? "" : ",dx_true1_m,dx_true2_m") << "\n";
    for (std::size_t k = 0; k < w.size(); ++k) {
      o << static_cast<double>(k) / w.fs_hz;
      for (const auto* v : {&w.dx, &w.dxd, &w.dxdd, &w.du_ext_adm, &w.du_ext_force, &w.u_pert})
        o << ',' << (*v)[k].x() << ',' << (*v)[k].y();
      if (!w.dx_true.empty()) o << ',' << w.dx_true[k].x() << ',' << w.dx_true[k].y();
      o << '\n';
    }
  }
}

void write_plots(const Report& r, const std::string& dir) {
  std::filesystem::create_directories(dir);
  if (!r.psd.f_hz.empty()) {
    std::vector<Series> s;
    if (r.psd.n_unperturbed) s.push_back({"unperturbed", r.psd.f_hz, r.psd.p_unperturbed, "#1f77b4"});
    if (r.psd.n_perturbed) s.push_back({"perturbed", r.psd.f_hz, r.psd.p_perturbed, "#d62728"});
    svg_plot(dir + "/psd_jerk_x2.svg", "PSD of principal-axis jerk (Fig. 3)", "f [Hz]", "PSD [(m/s^3)^2/Hz]", s, true, 10.0);
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
      if (s.method != m || s.group.rfind("angle ", 0) != 0) continue;
      ang.push_back(std::stod(s.group.substr(6)));
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

EstimatorSettings load_estimator_settings(const std::string& path, EstimatorSettings s) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw std::runtime_error(path + ": cannot open settings file");
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(path + ": YAML error at line " + std::to_string(e.mark.line + 1) + ": " + e.msg);
  }
  if (!root.IsMap()) throw std::runtime_error(path + ": top level must be a map");
  for (const auto& kv : root) {
    const auto key = kv.first.as<std::string>();
    const auto& v = kv.second;
    auto D = [&](auto& dst) { dst = get_as<std::decay_t<decltype(dst)>>(v, path, key); };
    if (key == "methods") {
      s.methods.clear();
      for (const auto& m : v) s.methods.push_back(get_as<std::string>(m, path, key));
      if (s.methods.size() == 1 && s.methods[0] == "all") s.methods = all_methods();
    } else if (key == "sg_order") D(s.pipeline.sg_order);
    else if (key == "sg_cutoff_hz") D(s.pipeline.sg_cutoff_hz);
    else if (key == "sg_window") D(s.pipeline.sg_window);
    else if (key == "hp_order") D(s.pipeline.hp_order);
    else if (key == "hp_cutoff_hz") {
      const auto str = get_as<std::string>(v, path, key);
      if (str == "auto") s.cutoff_auto = true;
      else { s.cutoff_auto = false; D(s.pipeline.hp_cutoff_hz); }
    } else if (key == "cutoff_auto_threshold_db") D(s.cutoff_auto_threshold_db);
    else if (key == "psd_nfft") D(s.psd_nfft);
    else if (key == "t_est_s") { D(s.pipeline.t_est_s); s.oe.t_est_s = s.pem.t_est_s = s.pipeline.t_est_s; }
    else if (key == "k_model") {
      const auto m = get_as<std::string>(v, path, key);
      if (m == "symmetric") s.ls.k_model = StiffnessModel::symmetric;
      else if (m == "full") s.ls.k_model = StiffnessModel::full;
      else throw std::runtime_error(path + ": k_model: must be 'symmetric' or 'full', not '" + m + "'");
    } else if (key == "estimate_m") D(s.ls.estimate_m);
    else if (key == "force_source") {
      const auto m = get_as<std::string>(v, path, key);
      if (m == "admittance") s.ls.force = ForceSource::admittance;
      else if (m == "sensor") s.ls.force = ForceSource::sensor;
      else throw std::runtime_error(path + ": force_source: must be 'admittance' or 'sensor', not '" + m + "'");
    } else if (key == "oe_t_pre_s") D(s.oe.t_pre_s);
    else if (key == "oe_poly_order") D(s.oe.poly_order);
    else if (key == "oe_max_iterations") D(s.oe.max_iterations);
    else if (key == "oe_jackknife") D(s.oe.jackknife);
    else if (key == "oe_prewhiten_order") D(s.oe.prewhiten_order);
    else if (key == "pem_t_pre_s") D(s.pem.t_pre_s);
    else if (key == "pem_max_iterations") D(s.pem.max_iterations);
    else if (key == "pem_structure") {
      const auto m = get_as<std::string>(v, path, key);
      if (m == "box-jenkins") s.pem.structure = PemStructure::box_jenkins;
      else if (m == "armax") s.pem.structure = PemStructure::armax;
      else throw std::runtime_error(path + ": pem_structure: must be 'box-jenkins' or 'armax', not '" + m + "'");
    } else if (key == "pem_se") {
      const auto m = get_as<std::string>(v, path, key);
      if (m == "sandwich") s.pem.se = PemSe::sandwich;
      else if (m == "fisher") s.pem.se = PemSe::fisher;
      else if (m == "jackknife") s.pem.se = PemSe::jackknife;
      else throw std::runtime_error(path + ": pem_se: must be 'sandwich', 'fisher' or 'jackknife', not '" + m + "'");
    } else throw std::runtime_error(path + ": " + key + ": unknown key");
  }
  auto bad = [&](bool cond, const char* key, const char* why) {
    if (cond) throw std::runtime_error(path + ": " + key + ": " + why);
  };
  bad(s.pipeline.sg_order < 1 || s.pipeline.sg_order > 10, "sg_order", "must be 1..10");
  bad(!(s.pipeline.sg_cutoff_hz > 0), "sg_cutoff_hz", "must be positive");
  bad(s.pipeline.sg_window != 0 && s.pipeline.sg_window % 2 == 0, "sg_window", "must be odd (or 0 for automatic)");
  bad(s.pipeline.hp_order < 1 || s.pipeline.hp_order > 10, "hp_order", "must be 1..10");
  bad(!(s.pipeline.hp_cutoff_hz > 0), "hp_cutoff_hz", "must be positive or 'auto'");
  bad(!(s.pipeline.t_est_s > 0 && s.pipeline.t_est_s <= 1.0), "t_est_s", "must be in (0, 1] s");
  bad(s.psd_nfft < 256, "psd_nfft", "must be >= 256");
  bad(!(s.oe.t_pre_s >= 0 && s.oe.t_pre_s <= 0.5), "oe_t_pre_s", "must be in [0, 0.5] s");
  bad(s.oe.poly_order < 0 || s.oe.poly_order > 8, "oe_poly_order", "must be 0..8");
  bad(s.oe.max_iterations < 1, "oe_max_iterations", "must be >= 1");
  bad(s.oe.prewhiten_order < 0 || s.oe.prewhiten_order > 20, "oe_prewhiten_order", "must be 0..20");
  bad(!(s.pem.t_pre_s >= 0.01 && s.pem.t_pre_s <= 0.5), "pem_t_pre_s", "must be in [0.01, 0.5] s");
  bad(s.pem.max_iterations < 1, "pem_max_iterations", "must be >= 1");
  return s;
}

}  // namespace manip::estimation
