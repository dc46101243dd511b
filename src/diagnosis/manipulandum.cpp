#include "manip/diagnosis/manipulandum.hpp"
#include "manip/diagnosis/report.hpp"
#include "manip/diagnosis/sensor_delay.hpp"
#include "manip/diagnosis/stats.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <sstream>
#include <utility>

#include "manip/common/errors.hpp"
#include "manip/dsp/savgol.hpp"
#include "manip/estimation/methods/method.hpp"
#include "manip/estimation/methods/registry.hpp"
#include "manip/estimation/pem.hpp"
#include "manip/estimation/tracking_input.hpp"
#include "manip/estimation/variational.hpp"
#include "manip/model/arm.hpp"

namespace manip::diagnosis {

using Eigen::Matrix2d;
using Eigen::Vector2d;

namespace {

// Per-trial nuisance polynomial (variable projection, Frisch-Waugh-Lovell):
// what the high-pass isolation leaves of the unperturbed movement in the
// window is smooth, p(t); it enters eq. 14 as −(M p̈ + (D + D_adm) ṗ + K p),
// a polynomial of the same order when p is one. Including a polynomial per
// trial and axis is the same as projecting it out of the target and of every
// column of that segment, which also holds for held-out trials (their
// polynomial is the trial's own nuisance, not a shared parameter). The `oe`
// method absorbs the unperturbed movement the same way (docs/estimator.md).
class Projector {
 public:
  Projector(std::size_t n, int order, double dt) {
    if (order < 0) return;
    Eigen::MatrixXd P(static_cast<Eigen::Index>(n), order + 1);
    const double T = static_cast<double>(n - 1) * dt;
    for (std::size_t k = 0; k < n; ++k) {
      const double x = 2.0 * static_cast<double>(k) * dt / T - 1.0;  // [-1, 1]: well conditioned
      double v = 1.0;
      for (int j = 0; j <= order; ++j, v *= x) P(static_cast<Eigen::Index>(k), j) = v;
    }
    Eigen::HouseholderQR<Eigen::MatrixXd> qr(P);
    q_ = qr.householderQ() * Eigen::MatrixXd::Identity(P.rows(), P.cols());
  }
  void apply(std::vector<double>& v) const {
    if (q_.size() == 0 || static_cast<Eigen::Index>(v.size()) != q_.rows()) return;
    Eigen::Map<Eigen::VectorXd> m(v.data(), static_cast<Eigen::Index>(v.size()));
    const Eigen::VectorXd c = q_.transpose() * m;
    m -= q_ * c;
  }

 private:
  Eigen::MatrixXd q_;
};

// A mechanism whose columns are projected like the dataset (see Projector).
class Projected final : public Mechanism {
 public:
  Projected(std::unique_ptr<Mechanism> inner, int order) : inner_(std::move(inner)), order_(order) {}
  std::string id() const override { return inner_->id(); }
  std::string title() const override { return inner_->title(); }
  std::string signature() const override { return inner_->signature(); }
  std::string not_applicable(const Dataset& d) const override { return inner_->not_applicable(d); }
  std::vector<ParamInfo> shape_params() const override { return inner_->shape_params(); }
  std::vector<ParamInfo> gains() const override { return inner_->gains(); }
  std::vector<std::vector<double>> grid(const Dataset& d) const override { return inner_->grid(d); }
  std::size_t history_samples(const Dataset& d) const override { return inner_->history_samples(d); }
  int main_param() const override { return inner_->main_param(); }
  LikelihoodPlan likelihood_plan(const Dataset& d, std::span<const double> s) const override { return inner_->likelihood_plan(d, s); }
  std::vector<std::vector<Eigen::Vector2d>> model_correction(const Dataset& d, std::span<const double> s, std::span<const double> g,
                                                             const Eigen::Matrix2d& dm, const Eigen::Matrix2d& km) const override {
    return inner_->model_correction(d, s, g, dm, km);
  }
  void next_reference(const Dataset& d, std::span<const double> s, std::span<const double> g, const Eigen::Matrix2d& d0,
                      const Eigen::Matrix2d& k0, Eigen::Matrix2d& d1, Eigen::Matrix2d& k1) const override {
    inner_->next_reference(d, s, g, d0, k0, d1, k1);
  }
  DerivedGain derived_gain() const override { return inner_->derived_gain(); }
  Columns columns(const Dataset& d, std::span<const double> s) const override {
    auto c = inner_->columns(d, s);
    if (order_ < 0 || c.empty()) return c;
    const Projector pr(d.segments.front().y.size(), order_, d.dt_s);
    for (auto& seg : c)
      for (auto& col : seg) pr.apply(col);
    return c;
  }
  [[nodiscard]] const Mechanism& inner() const { return *inner_; }

 private:
  std::unique_ptr<Mechanism> inner_;
  int order_;
};

const Mechanism& unprojected(const Mechanism& m) {
  const auto* p = dynamic_cast<const Projected*>(&m);
  return p ? p->inner() : m;
}

}  // namespace

LogCollector::LogCollector(CollectedSession& out)
    : out_(out), asmb_([this](const estimation::SessionInfo&, estimation::TrialData&& t) {
        ++out_.n_trials;
        if (t.perturbed) out_.perturbed.push_back(std::move(t));
      }) {
  // Unperturbed trials are not used (no PSD here): keep only their positions.
  asmb_.set_keep_unperturbed_signals(false);
}

void LogCollector::finish() {
  asmb_.finish();
  out_.has_session = asmb_.has_session();
  if (out_.has_session) out_.info = asmb_.session();
  out_.issues = asmb_.issues();
  out_.warnings = asmb_.warnings();
}

CollectedSession collect_log(const std::string& path) {
  CollectedSession s;
  s.name = path;
  LogCollector c(s);
  try {
    (void)logging::read_log(path, c);
    c.finish();
  } catch (const std::exception& e) {
    const std::string what = e.what();
    throw InputError(what.rfind(path, 0) == 0 ? what : path + ": " + what);
  }
  if (!s.has_session) throw InputError(path + ": no session message (not a manip session log?)");
  if (c.states_seen() == 0) throw InputError(path + ": no MANIP_STATE messages");
  return s;
}

namespace {

std::string num(double v) {
  std::ostringstream o;
  o.precision(6);
  o << v;
  return o.str();
}

}  // namespace

std::string configuration_difference(const estimation::SessionInfo& a, const estimation::SessionInfo& b) {
  auto cmp = [](double x, double y) { return std::fabs(x - y) <= 1e-9 * std::max({1.0, std::fabs(x), std::fabs(y)}); };
  auto d1 = [&](const char* name, double x, double y) -> std::string {
    return cmp(x, y) ? std::string{} : std::string(name) + ": " + num(x) + " vs " + num(y);
  };
  std::vector<std::string> diffs = {
      d1("sample_rate_hz", a.sample_rate_hz, b.sample_rate_hz),
      d1("m_adm_kg[0]", a.m_adm_kg.x(), b.m_adm_kg.x()),
      d1("m_adm_kg[1]", a.m_adm_kg.y(), b.m_adm_kg.y()),
      d1("d_adm_nspm[0]", a.d_adm_nspm.x(), b.d_adm_nspm.x()),
      d1("d_adm_nspm[1]", a.d_adm_nspm.y(), b.d_adm_nspm.y()),
      d1("m_handle_kg[0]", a.m_handle_kg.x(), b.m_handle_kg.x()),
      d1("m_handle_kg[1]", a.m_handle_kg.y(), b.m_handle_kg.y()),
      d1("frame.rot_rad", a.frame.rot_rad, b.frame.rot_rad),
      d1("frame.origin_in_shoulder_m[0]", a.frame.origin_in_shoulder_m.x(), b.frame.origin_in_shoulder_m.x()),
      d1("frame.origin_in_shoulder_m[1]", a.frame.origin_in_shoulder_m.y(), b.frame.origin_in_shoulder_m.y()),
      d1("perturbation.duration_s", a.perturbation.duration_s, b.perturbation.duration_s),
      d1("perturbation.amplitude_n", a.perturbation.amplitude_n, b.perturbation.amplitude_n),
      d1("perturbation.trigger_x2_shoulder_m", a.perturbation.trigger_x2_shoulder_m, b.perturbation.trigger_x2_shoulder_m),
  };
  for (int i = 0; i < 2; ++i) {
    const std::string k = "[" + std::to_string(i) + "]";
    diffs.push_back(d1(("anthropometrics.length_m" + k).c_str(), a.anthropometrics.length_m[i], b.anthropometrics.length_m[i]));
    diffs.push_back(d1(("anthropometrics.mass_kg" + k).c_str(), a.anthropometrics.mass_kg[i], b.anthropometrics.mass_kg[i]));
    diffs.push_back(d1(("anthropometrics.com_m" + k).c_str(), a.anthropometrics.com_m[i], b.anthropometrics.com_m[i]));
    diffs.push_back(d1(("anthropometrics.inertia_kgm2" + k).c_str(), a.anthropometrics.inertia_kgm2[i], b.anthropometrics.inertia_kgm2[i]));
  }
  for (const auto& d : diffs)
    if (!d.empty()) return d;
  return {};
}

namespace {

// The seven baseline columns of eq. 14 for row `a` (0: x1, 1: x2):
// D11 D12 D21 D22 K11 K12(=K21) K22.
void baseline_row(int a, const Vector2d& dxd, const Vector2d& dx, double out[7]) {
  out[0] = a == 0 ? dxd(0) : 0.0;
  out[1] = a == 0 ? dxd(1) : 0.0;
  out[2] = a == 1 ? dxd(0) : 0.0;
  out[3] = a == 1 ? dxd(1) : 0.0;
  out[4] = a == 0 ? dx(0) : 0.0;
  out[5] = a == 0 ? dx(1) : dx(0);
  out[6] = a == 1 ? dx(1) : 0.0;
}

// I[u_pert] for the force-sensor delay fit (sensor_delay.hpp): the held
// command's exact double integral (v += u dt, x += v dt + u dt²/2 per cycle)
// as the trial's position, isolated by the estimator's own code from
// kSensorDelayMaxS (+1 ms) before onset, so that the fit can delay it.
// Trials with too little before onset keep it empty (the fit skips them).
void isolated_u_pert(const estimation::SessionInfo& info, const estimation::TrialData& trial,
                     const estimation::PipelineSettings& pipeline, PlanarTrial& p) {
  const double fs = info.sample_rate_hz, dt = 1.0 / fs;
  const auto pre = static_cast<std::size_t>(std::ceil((kSensorDelayMaxS + 0.001) * fs));
  const auto on = static_cast<std::size_t>(trial.onset_index);
  if (trial.onset_index < 0 || on < pre || trial.u_pert_n.size() != trial.x_m.size()) return;
  estimation::TrialData g = trial;
  Vector2d v = Vector2d::Zero(), x = Vector2d::Zero();
  for (std::size_t i = 0; i < g.x_m.size(); ++i) {
    g.x_m[i] = x;
    const Vector2d& u = trial.u_pert_n[i];
    x += v * dt + u * (0.5 * dt * dt);
    v += u * dt;
  }
  g.onset_index = static_cast<std::int64_t>(on - pre);
  estimation::PipelineSettings ps = pipeline;
  const auto n_win = static_cast<std::size_t>(std::llround(pipeline.t_est_s * fs)) + 1;
  ps.t_est_s = static_cast<double>(n_win - 1 + pre) / fs;
  try {
    p.u_pert_iso = estimation::isolate_variational(info, g, ps).dxdd;
    p.u_pert_iso_pre = pre;
  } catch (const std::invalid_argument&) {
    p.u_pert_iso.clear();  // too short after onset for the longer window: the fit skips the trial
  }
}

// The tracking column (dataset.hpp, PlanarTrial::tracking_iso): the aligned
// reference through the estimator's isolation, against the encoder's. A log
// without a finite reference (imports) leaves it empty; with the estimator
// already on the reference (--position-source reference) it is zero.
void isolated_tracking(const estimation::SessionInfo& info, const estimation::TrialData& trial,
                       const estimation::PipelineSettings& pipeline, PlanarTrial& p) {
  estimation::TrialData g = trial;
  try {
    p.reference_shift = estimation::reference_shift_for(info.source);
    g.x_m = estimation::aligned_reference(trial, p.reference_shift);
    const auto vr = estimation::isolate_variational(info, g, pipeline);
    const std::size_t n = std::min(vr.size(), p.dx.size());
    p.tracking_iso.resize(n);
    p.x_track.resize(n);
    const auto on = static_cast<std::size_t>(trial.onset_index);
    for (std::size_t k = 0; k < n; ++k) {
      p.tracking_iso[k] = p.m_adm * (vr.dxdd[k] - p.dxdd[k]) + p.d_adm * (vr.dxd[k] - p.dxd[k]);
      p.x_track[k] = g.x_m.at(on + k) - trial.x_m.at(on + k);
    }
  } catch (const std::invalid_argument&) {
    p.tracking_iso.clear();
    p.x_track.clear();
    p.reference_shift = -1;
  }
}

// Whether the default method reads the output-error and the prediction-error
// windows (estimation::Method::windows).
std::pair<bool, bool> default_method_windows() {
  const estimation::Method* m = estimation::find_method(estimation::default_method());
  return {m && estimation::needs(m->windows(), estimation::DataWindow::output_error),
          m && estimation::needs(m->windows(), estimation::DataWindow::prediction_error)};
}
}  // namespace

PlanarPrepared prepare_planar(std::vector<CollectedSession>& sessions, const PlanarOptions& opt, int folds) {
  if (sessions.empty()) throw InputError("no session log given");
  // The library's columns and the likelihood's corrections are built on one
  // position; "tracked" (two, tracking_input.hpp) is the estimator's.
  if (opt.estimator.position == estimation::PositionSource::tracked)
    throw std::invalid_argument("the diagnosis runs on the encoder or the reference (position auto, encoder or reference), not tracked");
  for (std::size_t i = 1; i < sessions.size(); ++i) {
    const auto diff = configuration_difference(sessions[0].info, sessions[i].info);
    if (!diff.empty())
      throw InputError(sessions[0].name + " and " + sessions[i].name +
                       " have different session configurations (" + diff +
                       "): diagnose them separately, they are never pooled");
  }
  PlanarPrepared out;
  const auto& info0 = sessions[0].info;
  const double fs = info0.sample_rate_hz;
  out.t_est_s = opt.estimator.pipeline.t_est_s;
  out.sg_window = estimation::sg_window_for(opt.estimator.pipeline, fs);
  Dataset& d = out.data;
  d.dt_s = 1.0 / fs;
  d.smoother = nullptr;  // the estimator's pipeline has already filtered every signal
  d.smoothing_cutoff_hz = opt.estimator.pipeline.sg_cutoff_hz;
  d.target_name = "du_ext - M_BSP ddx (eq. 14)";
  d.target_unit = "N";
  d.kin_unit = "m";
  d.base_names = {"D11", "D12", "D21", "D22", "K11", "K12", "K22"};
  d.base_units = {"N s/m", "N s/m", "N s/m", "N s/m", "N/m", "N/m", "N/m"};
  d.pos_ref = 0.0;
  for (std::size_t i = 0; i < sessions.size(); ++i) d.source += (i ? ", " : "") + sessions[i].name;

  out.info = info0;
  out.settings = opt.estimator;
  out.settings.methods = {estimation::default_method()};
  const auto [want_oe, want_pw] = default_method_windows();
  for (auto& ses : sessions) {
    out.logs.push_back(ses.name);
    out.n_trials += ses.n_trials;
    out.n_perturbed += static_cast<int>(ses.perturbed.size());
    for (const auto& is : ses.issues) out.excluded.push_back(ses.name + ": trial " + std::to_string(is.trial) + ": " + is.reason);
    const TwoLinkArm arm(ses.info.anthropometrics);
    const Matrix2d rot = ses.info.frame.rotation();
    for (auto& t : ses.perturbed) {
      PlanarTrial p;
      p.trial = t.trial;
      p.log = ses.name;
      p.angle_rad = t.angle_rad;
      p.ws_to_sh = rot;
      p.m_adm = ses.info.m_adm_shoulder_kg();
      p.d_adm = ses.info.d_adm_shoulder_nspm();
      p.m_handle = ses.info.m_handle_shoulder_kg();
      try {
        // --position-source reference: the diagnosis sees what the estimator would.
        if (opt.estimator.position == estimation::PositionSource::reference)
          t.x_m = estimation::aligned_reference(t, estimation::reference_shift_for(ses.info.source));
        if (t.onset_index < 0) throw std::invalid_argument("no onset");
        const auto on = static_cast<std::size_t>(t.onset_index);
        const auto m_bsp = arm.endpoint_inertia_at(t.x_m.at(on));
        if (!m_bsp) throw std::invalid_argument("onset position out of the arm's reach");
        p.m_bsp = *m_bsp;
        auto vw = estimation::isolate_variational(ses.info, t, opt.estimator.pipeline);
        if (opt.pem_baseline) {
          if (want_oe) out.oe.push_back(estimation::make_oe_window(ses.info, t, *m_bsp, out.settings.oe));
          if (want_pw) out.pw.push_back(estimation::make_pem_window(ses.info, t, *m_bsp, out.settings.pem));
        }
        p.dx = vw.dx;
        p.dxd = vw.dxd;
        p.dxdd = vw.dxdd;
        p.du_ext_adm = vw.du_ext_adm;
        p.du_ext_force = vw.du_ext_force;
        p.u_pert = vw.u_pert;
        const std::size_t n = vw.size();
        p.u_pert_rate.resize(n);
        p.xd_stage.resize(n);
        // Rate of the logged (zero-order-held) force: central difference over
        // the trial's samples (u_pert is 0 before onset).
        for (std::size_t k = 0; k < n; ++k) {
          const std::size_t i = on + k;
          const std::size_t lo = i > 0 ? i - 1 : i, hi = std::min(i + 1, t.u_pert_n.size() - 1);
          p.u_pert_rate[k] = (t.u_pert_n[hi] - t.u_pert_n[lo]) / (static_cast<double>(hi - lo) * d.dt_s);
          p.xd_stage[k] = t.xd_ref_m.at(i);
        }
        p.friction_iso = isolated_stage_friction(ses.info, t, opt.estimator.pipeline, rot);
        isolated_u_pert(ses.info, t, opt.estimator.pipeline, p);
        isolated_tracking(ses.info, t, opt.estimator.pipeline, p);
        if (opt.pem_baseline) {
          out.vw.push_back(std::move(vw));
          out.m_bsp.push_back(*m_bsp);
        }
      } catch (const std::exception& e) {
        out.excluded.push_back(ses.name + ": trial " + std::to_string(t.trial) + ": " + e.what());
        continue;
      }
      const int g = static_cast<int>(d.planar.size());
      const double t0 = static_cast<double>(t.start_cycle + t.onset_index) * d.dt_s;
      for (int a = 0; a < 2; ++a) {
        Segment s;
        s.t0_s = t0;
        s.group = g;
        s.axis = a;
        s.planar = g;
        const std::size_t n = p.dx.size();
        s.y.resize(n);
        s.pos.resize(n);
        s.vel.resize(n);
        s.acc.resize(n);
        s.base.assign(7, std::vector<double>(n));
        for (std::size_t k = 0; k < n; ++k) {
          s.y[k] = p.du_ext_adm[k](a) - (p.m_bsp * p.dxdd[k])(a);
          s.pos[k] = p.dx[k](a);
          s.vel[k] = p.dxd[k](a);
          s.acc[k] = p.dxdd[k](a);
          double row[7];
          baseline_row(a, p.dxd[k], p.dx[k], row);
          for (int c = 0; c < 7; ++c) s.base[static_cast<std::size_t>(c)][k] = row[c];
        }
        s.pos_raw = s.pos;
        if (opt.nuisance_order >= 0) {
          const Projector pr(n, opt.nuisance_order, d.dt_s);
          pr.apply(s.y);
          for (auto& c : s.base) pr.apply(c);
        }
        s.first = 0;
        s.last = n;
        d.segments.push_back(std::move(s));
      }
      d.planar.push_back(std::move(p));
    }
    ses.perturbed.clear();
  }
  const int usable = static_cast<int>(d.planar.size());
  if (usable < folds)
    throw InputError(d.source + ": " + std::to_string(usable) + " usable perturbed trial" + (usable == 1 ? "" : "s") +
                     " (of " + std::to_string(out.n_perturbed) + " perturbed): the " + std::to_string(folds) +
                     "-fold cross-validation over trials needs at least " + std::to_string(folds) +
                     " (e.g. manip_sim --movements 100 gives 24)");
  out.sensor_delay = sensor_delay(d);
  if (opt.pem_baseline) out.pem = fit_default_method(out);
  if (out.pem.available) {
    d.planar_ref_d = out.pem.d;
    d.planar_ref_k = out.pem.k;
  } else {
    const auto f = fit_full(d, {});
    d.planar_ref_d << f.theta(0), f.theta(1), f.theta(2), f.theta(3);
    d.planar_ref_k << f.theta(4), f.theta(5), f.theta(5), f.theta(6);
  }
  return out;
}

namespace {
void apply_correction(std::vector<estimation::OeWindow>& ws, const std::vector<std::vector<Vector2d>>* correction) {
  if (!correction) return;
  for (std::size_t i = 0; i < ws.size() && i < correction->size(); ++i) {
    auto& w = ws[i];
    const auto& c = (*correction)[i];
    for (std::size_t k = 0; k < c.size(); ++k) {
      const auto j = static_cast<std::size_t>(w.onset_offset) + k;
      if (j < w.u_n.size()) w.u_n[j] -= c[k];
    }
  }
}
}  // namespace

std::vector<estimation::OeWindow> corrected_pem_windows(const PlanarPrepared& prep, const std::vector<std::vector<Vector2d>>* correction) {
  auto pw = prep.pw;
  apply_correction(pw, correction);
  return pw;
}

namespace {
// The default method on position "tracked", trial by trial as
// SessionEstimator::prepare builds it (a trial it cannot use is left out, as
// the estimator excludes it); the sessions are left as they are.
PemBaseline fit_tracked(const std::vector<CollectedSession>& sessions, const PlanarOptions& opt) {
  PlanarPrepared tp;
  tp.info = sessions[0].info;
  tp.settings = opt.estimator;
  tp.settings.position = estimation::PositionSource::tracked;
  tp.settings.methods = {estimation::default_method()};
  const auto [want_oe, want_pw] = default_method_windows();
  const auto& pipe = tp.settings.pipeline;
  for (const auto& ses : sessions) {
    const TwoLinkArm arm(ses.info.anthropometrics);
    const int shift = estimation::reference_shift_for(ses.info.source);
    for (const auto& t : ses.perturbed) {
      try {
        if (t.onset_index < 0) continue;
        const auto m_bsp = arm.endpoint_inertia_at(t.x_m.at(static_cast<std::size_t>(t.onset_index)));
        if (!m_bsp) continue;
        const auto x_ref = estimation::aligned_reference(t, shift);
        auto vw = estimation::isolate_variational(ses.info, t, pipe);
        estimation::OeWindow ow, pw;
        if (want_oe) ow = estimation::make_oe_window(ses.info, t, *m_bsp, tp.settings.oe);
        if (want_pw) pw = estimation::make_pem_window(ses.info, t, *m_bsp, tp.settings.pem);
        estimation::OeWindow* const w[] = {&ow, &pw};
        estimation::add_tracking_input(ses.info, t, x_ref, pipe, vw, w);
        tp.vw.push_back(std::move(vw));
        tp.m_bsp.push_back(*m_bsp);
        if (want_oe) tp.oe.push_back(std::move(ow));
        if (want_pw) tp.pw.push_back(std::move(pw));
      } catch (const std::exception&) {
        continue;
      }
    }
  }
  if (tp.vw.empty()) {
    PemBaseline r;
    r.error = "no trial with a finite admittance reference";
    return r;
  }
  return fit_default_method(tp);
}
}  // namespace

PlanarPrepared prepare_planar_tracked(std::vector<CollectedSession>& sessions, const PlanarOptions& opt, int folds,
                                      const std::function<void(const std::string&)>& progress) {
  // prepare_planar consumes the sessions: keep them while the move is possible.
  // "auto" (the default) starts on the encoder and lets the data decide;
  // an explicit encoder or reference stays where it is.
  const bool may_move = opt.estimator.position == estimation::PositionSource::automatic;
  std::vector<CollectedSession> kept;
  if (may_move) kept = sessions;
  PlanarPrepared prep = prepare_planar(sessions, opt, folds);
  const auto& sd = prep.sensor_delay;
  if (!may_move || !sd.available || !(sd.tracking_share >= kTrackingMinShare) ||
      !(std::fabs(sd.tracking_coef - 1.0) <= kTrackingCoefTolerance) || !(sd.tracking_heldout_share > 0.0))
    return prep;
  TrackingSwitch sw;
  sw.switched = true;
  sw.share = sd.tracking_share;
  sw.coef = sd.tracking_coef;
  sw.heldout_share = sd.tracking_heldout_share;
  sw.heldout_better = sd.tracking_heldout_better;
  sw.trials = sd.trials;
  const auto ts = tracking_summary(prep);
  sw.rms_um = ts.rms_um;
  sw.shift0 = ts.shift0;
  sw.shift1 = ts.shift1;
  sw.on_encoder = prep.pem;
  if (opt.pem_baseline) sw.on_tracked = fit_tracked(kept, opt);
  if (progress) progress("the stages' tracking is most of eq. 21's disagreement with the force sensor: moving to the admittance reference");
  PlanarOptions on_ref = opt;
  on_ref.estimator.position = estimation::PositionSource::reference;
  prep = prepare_planar(kept, on_ref, folds);
  prep.tracking = sw;
  return prep;
}

TrackingSummary tracking_summary(const PlanarPrepared& prep) {
  TrackingSummary s;
  double ss = 0.0;
  std::size_t n = 0;
  for (const auto& p : prep.data.planar) {
    if (p.reference_shift < 0) continue;
    ++s.trials;
    (p.reference_shift == 0 ? s.shift0 : s.shift1) += 1;
    for (const auto& e : p.x_track) ss += e.squaredNorm();
    n += 2 * p.x_track.size();
  }
  if (n > 0) s.rms_um = 1e6 * std::sqrt(ss / static_cast<double>(n));
  return s;
}

PemBaseline fit_default_method(const PlanarPrepared& prep, const std::vector<std::vector<Vector2d>>* correction,
                               const std::vector<std::size_t>* trials, const PemBaseline* start) {
  PemBaseline r;
  r.method = prep.settings.methods.empty() ? estimation::default_method() : prep.settings.methods[0];
  const estimation::Method* m = estimation::find_method(r.method);
  if (!m) {
    r.error = "method " + r.method + " not registered";
    return r;
  }
  auto oe = prep.oe;
  auto pw = prep.pw;
  apply_correction(oe, correction);
  apply_correction(pw, correction);
  estimation::SessionWindows sw;
  sw.info = &prep.info;
  sw.settings = &prep.settings;
  estimation::EstimatorSettings warm;  // a copy only when there is a start
  if (start && start->available && start->has_likelihood) {
    warm = prep.settings;
    warm.pem.warm_start = true;
    warm.pem.start_d_nspm = start->d;
    warm.pem.start_k_npm = start->k;
    warm.pem.start_disturbance = start->noise;
    warm.pem.tolerance_nats = 1e-3;
    sw.settings = &warm;
  }
  sw.variational = prep.vw;
  sw.m_bsp = prep.m_bsp;
  sw.output_error = oe;
  sw.prediction_error = pw;
  std::vector<std::size_t> idx(prep.vw.size());
  for (std::size_t i = 0; i < idx.size(); ++i) idx[i] = i;
  if (trials) idx = *trials;
  try {
    const auto e = m->fit(sw, {idx, nullptr});
    r.available = true;
    r.d = e.d_nspm;
    r.k = e.k_npm;
    r.d_lo = e.d_nspm - e.ci_factor * e.d_se;
    r.d_hi = e.d_nspm + e.ci_factor * e.d_se;
    r.k_lo = e.k_npm - e.ci_factor * e.k_se;
    r.k_hi = e.k_npm + e.ci_factor * e.k_se;
    if (e.disturbance) {
      r.has_likelihood = true;
      r.neg_log_likelihood = e.disturbance->neg_log_likelihood;
      r.noise = *e.disturbance;
    }
  } catch (const std::exception& ex) {
    r.error = ex.what();
  }
  return r;
}

namespace {
RefinedExtension refine_core(const PlanarPrepared& prep,
                             const std::function<std::vector<std::vector<Vector2d>>(double)>& correction_at,
                             const std::function<void(const std::string&)>& progress) {
  RefinedExtension r;
  auto eval = [&](double alpha) {
    const auto c = correction_at(alpha);
    ++r.evaluations;
    return fit_default_method(prep, &c, nullptr, &prep.pem);
  };
  const auto f1 = eval(1.0);
  if (!f1.available || !f1.has_likelihood || !prep.pem.has_likelihood) {
    r.fit = f1;
    return r;
  }
  r.nll_baseline = prep.pem.neg_log_likelihood;
  r.nll_alpha1 = f1.neg_log_likelihood;
  // The correction enters the model's input linearly, so with D, K (and the
  // noise model) re-fitted the negative log-likelihood is close to a
  // parabola in α: successive parabolic interpolation through the three best
  // points (α = 0 is the plain fit, already done), two steps, α in [0, 3].
  auto nll = [](const PemBaseline& p) { return p.available && p.has_likelihood ? p.neg_log_likelihood : 1e300; };
  std::vector<std::pair<double, PemBaseline>> pts = {{0.0, prep.pem}, {1.0, f1}};
  pts.emplace_back(2.0, eval(2.0));
  for (int step = 0; step < 2; ++step) {
    if (progress) progress("refining the extension's amplitude by the default method's likelihood (step " + std::to_string(step + 1) + " of 2)");
    std::sort(pts.begin(), pts.end(), [&](const auto& x, const auto& y) { return nll(x.second) < nll(y.second); });
    const double xa = pts[0].first, xb = pts[1].first, xc = pts[2].first;
    const double fa = nll(pts[0].second), fb = nll(pts[1].second), fc = nll(pts[2].second);
    double xn = stats::parabola_vertex(xa, fa, xb, fb, xc, fc);
    if (!std::isfinite(xn)) xn = xa;
    xn = std::clamp(xn, 0.0, 3.0);
    bool seen = false;
    for (const auto& p : pts) seen = seen || std::fabs(p.first - xn) < 1e-3;
    if (seen) break;
    pts.emplace_back(xn, eval(xn));
  }
  std::sort(pts.begin(), pts.end(), [&](const auto& x, const auto& y) { return nll(x.second) < nll(y.second); });
  r.available = true;
  r.alpha = pts[0].first;
  r.fit = pts[0].second;
  r.nll_best = nll(r.fit);
  return r;
}
}  // namespace

RefinedExtension refine_with_default_method(const PlanarPrepared& prep, const std::vector<std::vector<Vector2d>>& correction,
                                            const std::function<void(const std::string&)>& progress) {
  return refine_core(
      prep,
      [&](double alpha) {
        auto c = correction;
        for (auto& t : c)
          for (auto& v : t) v *= alpha;
        return c;
      },
      progress);
}

RefinedExtension refine_with_default_method(const PlanarPrepared& prep, const Diagnosis& dg,
                                            const std::vector<std::unique_ptr<Mechanism>>& lib,
                                            const std::function<void(const std::string&)>& progress) {
  return refine_core(prep, [&](double alpha) { return extension_correction(prep.data, dg, lib, alpha); }, progress);
}

std::vector<std::vector<Vector2d>> extension_correction(const Dataset& d, const Diagnosis& dg,
                                                       const std::vector<std::unique_ptr<Mechanism>>& lib) {
  return extension_correction(d, dg, lib, 1.0);
}

std::vector<std::vector<Vector2d>> extension_correction(const Dataset& d, const Diagnosis& dg,
                                                       const std::vector<std::unique_ptr<Mechanism>>& lib, double alpha) {
  std::vector<Columns> cols;
  for (std::size_t a = 0; a < dg.accepted.size(); ++a)
    for (const auto& m : lib)
      if (m->id() == dg.accepted[a]) cols.push_back(m->columns(d, dg.accepted_settings[a]));
  std::vector<const Columns*> ext;
  for (const auto& c : cols) ext.push_back(&c);
  const auto f = fit_full(d, ext);
  // The gains come from the fit of the (projected) dataset; the correction of
  // u_pert is built from the mechanisms' own, unprojected columns, except the
  // actuation delay, whose correction is exact: u(t) − u(t − α τ) (linear
  // interpolation between samples; u = 0 before onset), not its first-order
  // form τ u̇ that the equation-error fit uses.
  std::vector<std::vector<Vector2d>> out(d.planar.size());
  for (std::size_t i = 0; i < d.planar.size(); ++i) out[i].assign(d.planar[i].dx.size(), Vector2d::Zero());
  auto c = static_cast<Eigen::Index>(d.n_base());
  for (std::size_t a = 0; a < dg.accepted.size(); ++a) {
    const Mechanism* mech = nullptr;
    for (const auto& m : lib)
      if (m->id() == dg.accepted[a]) mech = &unprojected(*m);
    if (!mech) continue;
    const auto ng = static_cast<Eigen::Index>(mech->gains().size());
    if (mech->id() == "actuation_delay") {
      const double tau = alpha * f.theta(c);
      for (std::size_t i = 0; i < d.planar.size(); ++i) {
        const auto& u = d.planar[i].u_pert;
        for (std::size_t k = 0; k < u.size(); ++k) {
          const double t = static_cast<double>(k) - tau / d.dt_s;  // sample index of t − τ
          Vector2d ud = Vector2d::Zero();
          if (t >= 0) {
            const auto k0 = static_cast<std::size_t>(std::floor(t));
            const double w = t - static_cast<double>(k0);
            const Vector2d u0 = u[std::min(k0, u.size() - 1)], u1 = u[std::min(k0 + 1, u.size() - 1)];
            ud = (1 - w) * u0 + w * u1;
          } else if (t > -1) {  // between the sample before onset (0) and onset
            ud = (1 + t) * u[0];
          }
          out[i][k] += u[k] - ud;
        }
      }
    } else if (mech->id() == "stage_friction") {
      // The default method models the raw positions of [onset − t_pre, onset
      // + T_est] (no SG, no high-pass), the unperturbed movement as its
      // disturbance: the friction force it should be given is the unfiltered
      // change since onset, F [tanh(v(t)/v_s) − tanh(v(t_onset)/v_s)] per
      // workspace axis (the unperturbed run keeps its onset value unless it
      // reverses in the window; that part stays in the disturbance).
      const double F = alpha * f.theta(c), vs = dg.accepted_settings[a].at(0);
      for (std::size_t i = 0; i < d.planar.size(); ++i) {
        const auto& p = d.planar[i];
        const Matrix2d sh_to_ws = p.ws_to_sh.transpose();
        auto th = [&](const Vector2d& v_sh) {
          const Vector2d v = sh_to_ws * v_sh;
          return Vector2d(std::tanh(v(0) / vs), std::tanh(v(1) / vs));
        };
        const Vector2d t0 = th(p.xd_stage.front());
        for (std::size_t k = 0; k < p.xd_stage.size() && k < out[i].size(); ++k) out[i][k] += F * (p.ws_to_sh * (th(p.xd_stage[k]) - t0));
      }
    } else {
      const auto raw = mech->columns(d, dg.accepted_settings[a]);
      for (std::size_t s = 0; s < d.segments.size(); ++s) {
        const auto& g = d.segments[s];
        for (Eigen::Index j = 0; j < ng; ++j) {
          const double th = alpha * f.theta(c + j);
          const auto& col = raw[s][static_cast<std::size_t>(j)];
          for (std::size_t k = 0; k < col.size(); ++k) out[static_cast<std::size_t>(g.planar)][k](g.axis) += th * col[k];
        }
      }
    }
    c += ng;
  }
  return out;
}

std::vector<std::vector<Vector2d>> simulate_extension(const Dataset& d, const Matrix2d& d_nspm, const Matrix2d& k_npm,
                                                      const std::function<LinearExtension(const PlanarTrial&)>& extension) {
  constexpr int kSub = 8;
  const double h = d.dt_s / kSub;
  std::vector<std::vector<Vector2d>> out(d.planar.size());
  std::vector<Vector2d> hx, hv;  // state at every step start (delayed terms)
  for (std::size_t i = 0; i < d.planar.size(); ++i) {
    const auto& p = d.planar[i];
    const std::size_t n = p.u_pert.size();
    out[i].assign(n, Vector2d::Zero());
    const LinearExtension e = extension(p);
    const Matrix2d m_tot = p.m_adm + p.m_handle + p.m_bsp;
    const Matrix2d m_person = p.m_bsp + p.m_handle + e.mass_kg;
    const bool lag = e.sensor_lag_s > 0;
    const Matrix2d m_sys = lag ? p.m_adm : Matrix2d(m_tot + e.mass_kg);
    const Eigen::SelfAdjointEigenSolver<Matrix2d> es(0.5 * (m_sys + m_sys.transpose()));
    if (!(es.eigenvalues().minCoeff() > 1e-3) || !std::isfinite(e.sensor_lag_s) || !(d.dt_s > 0)) continue;
    const Matrix2d m_sys_inv = m_sys.inverse();
    const bool delayed = !e.damping_delayed_nspm.isZero() || !e.stiffness_delayed_npm.isZero();
    const bool one_sided = !e.delayed_one_sided_along.isZero();
    const long lag_steps = delayed ? std::max(1L, std::lround(e.delay_s / d.dt_s)) * kSub : 0;
    if (delayed) {
      hx.assign(n * kSub + 1, Vector2d::Zero());
      hv = hx;
    }
    // Delayed state at step index `at` (fractional; zero before onset).
    auto past = [&](double at, Vector2d& xd, Vector2d& vd) {
      xd.setZero();
      vd.setZero();
      if (!delayed || at < 0) return;
      const auto j = static_cast<std::size_t>(at);
      const double w = at - static_cast<double>(j);
      const std::size_t j1 = std::min(j + 1, hx.size() - 1);
      xd = (1 - w) * hx[j] + w * hx[j1];
      vd = (1 - w) * hv[j] + w * hv[j1];
    };
    Vector2d x = Vector2d::Zero(), v = Vector2d::Zero(), f = Vector2d::Zero();
    for (std::size_t k = 0; k < n; ++k) {
      const Vector2d u = p.u_pert[k];
      // Derivatives at a state (a, ḟ_r) and the baseline's residual there.
      auto deriv = [&](const Vector2d& x0, const Vector2d& v0, const Vector2d& f0, double at, Vector2d& a, Vector2d& df) {
        Vector2d xd, vd;
        past(at, xd, vd);
        Vector2d rest;
        if (one_sided) {
          const Vector2d& w = e.delayed_one_sided_along;
          const Vector2d copy = e.damping_delayed_nspm * vd + e.stiffness_delayed_npm * xd;
          rest = d_nspm * v0 + (k_npm + e.stiffness_npm) * x0 + e.delayed_gain * Vector2d(w * std::max(0.0, w.dot(copy)));
        } else {  // summed term by term as before the one-sided form: the same rounding, the same results
          rest = d_nspm * v0 + (k_npm + e.stiffness_npm) * x0 + e.delayed_gain * e.damping_delayed_nspm * vd +
                 e.delayed_gain * e.stiffness_delayed_npm * xd;
        }
        if (lag) {
          a = m_sys_inv * (f0 + u - p.d_adm * v0);
          df = (-m_person * a - rest - f0) / e.sensor_lag_s;
        } else {
          a = m_sys_inv * (u - p.d_adm * v0 - rest);
          df.setZero();
        }
        return Vector2d(u - m_tot * a - (d_nspm + p.d_adm) * v0 - k_npm * x0);
      };
      Vector2d mean = Vector2d::Zero();
      for (int j = 0; j < kSub; ++j) {
        const std::size_t m = k * kSub + static_cast<std::size_t>(j);
        if (delayed) {
          hx[m] = x;
          hv[m] = v;
        }
        const double at = static_cast<double>(m) - static_cast<double>(lag_steps);
        Vector2d a1, f1, a2, f2, a3, f3, a4, f4;
        const Vector2d c1 = deriv(x, v, f, at, a1, f1);
        const Vector2d x2 = v + 0.5 * h * a1;
        const Vector2d c2 = deriv(x + 0.5 * h * v, x2, f + 0.5 * h * f1, at + 0.5, a2, f2);
        const Vector2d x3 = v + 0.5 * h * a2;
        const Vector2d c3 = deriv(x + 0.5 * h * x2, x3, f + 0.5 * h * f2, at + 0.5, a3, f3);
        const Vector2d x4 = v + h * a3;
        const Vector2d c4 = deriv(x + h * x3, x4, f + h * f3, at + 1.0, a4, f4);
        mean += (c1 + 2 * c2 + 2 * c3 + c4) / 6.0;  // Simpson over the step
        x += h / 6 * (v + 2 * x2 + 2 * x3 + x4);
        v += h / 6 * (a1 + 2 * a2 + 2 * a3 + a4);
        f += h / 6 * (f1 + 2 * f2 + 2 * f3 + f4);
      }
      out[i][k] = mean / kSub;
    }
  }
  return out;
}

// ---------------------------------------------------------------- mechanisms
namespace {

// Columns built sample by sample from a segment's planar trial and axis.
template <class F>
Columns planar_columns(const Dataset& d, std::size_t ncol, F&& f) {
  Columns c(d.segments.size());
  for (std::size_t s = 0; s < d.segments.size(); ++s) {
    const auto& g = d.segments[s];
    const auto& p = d.planar[static_cast<std::size_t>(g.planar)];
    c[s].assign(ncol, std::vector<double>(g.y.size(), 0.0));
    for (std::size_t k = 0; k < g.y.size(); ++k) f(p, g.axis, k, c[s], k);
  }
  return c;
}

std::string planar_only(const Dataset& d) { return d.is_planar() ? std::string{} : "manipulandum sessions only"; }

// Antisymmetric (curl) stiffness (paper §3.3 assumes K symmetric): heteronymous
// reflexes make K12 != K21. K = K_sym + [0 c; -c 0], so row 1 gets c Δx2 and
// row 2 gets -c Δx1.
class Curl final : public Mechanism {
 public:
  std::string id() const override { return "curl_stiffness"; }
  std::string title() const override { return "antisymmetric (curl) stiffness: K = K_sym + [0 c; -c 0]"; }
  std::string signature() const override {
    return "axis-1 residual follows +Δx2 and axis-2 residual follows -Δx1 (a rotational force field)";
  }
  std::string not_applicable(const Dataset& d) const override { return planar_only(d); }
  // Arm stiffness asymmetry: |K12 - K21| up to ~1/3 of |K| (Mussa-Ivaldi,
  // Hogan & Bizzi 1985 found it small at rest; heteronymous reflexes can add
  // tens of N/m): +-300 N/m.
  std::vector<ParamInfo> gains() const override { return {{"curl_c", "N/m", -300.0, 300.0}}; }
  int main_param() const override { return 0; }
  std::vector<std::vector<Vector2d>> model_correction(const Dataset& d, std::span<const double>, std::span<const double> g,
                                                      const Matrix2d& dm, const Matrix2d& km) const override {
    LinearExtension e;
    const double c = g.empty() ? 0.0 : g[0];
    e.stiffness_npm << 0.0, c, -c, 0.0;
    return simulate_extension(d, dm, km, [&](const PlanarTrial&) { return e; });
  }
  Columns columns(const Dataset& d, std::span<const double>) const override {
    return planar_columns(d, 1, [](const PlanarTrial& p, int a, std::size_t k, auto& c, std::size_t i) {
      c[0][i] = a == 0 ? p.dx[k](1) : -p.dx[k](0);
    });
  }
};

// Actuation delay: the handle feels u_pert(t - tau), the log (and eq. 21)
// u_pert(t). Then eq. 14 computed from the log reads
//   Δu_ext − M_BSP Δẍ = D Δẋ + K Δx + u_pert(t) − u_pert(t − tau)
//                     = D Δẋ + K Δx + tau u̇_pert(t) + O(tau² ü_pert),
// linear in tau; the O(tau²) term is tau ü/(2 u̇) ≈ tau / T_rise relative
// (< 5 % for tau <= 5 ms with the paper's 150 ms pulse, eq. 22).
class ActuationDelay final : public Mechanism {
 public:
  std::string id() const override { return "actuation_delay"; }
  std::string title() const override { return "actuation delay: the perturbation force arrives tau after it is logged"; }
  std::string signature() const override {
    return "residual proportional to the perturbation force's rate u̇_pert: early in the window (rise of the pulse), "
           "and eq. 21 disagrees with the force sensor the same way";
  }
  std::string not_applicable(const Dataset& d) const override { return planar_only(d); }
  // Drive + bus latency of a position-controlled stage: ~0.5-2 cycles of
  // 4 kHz plus the drive's 2 kHz command rate (paper §5.1); 20 ms bounds
  // anything a working rig could have.
  std::vector<ParamInfo> gains() const override { return {{"delay", "s", 0.0, 0.020}}; }
  int main_param() const override { return 0; }
  Columns columns(const Dataset& d, std::span<const double>) const override {
    return planar_columns(d, 1, [](const PlanarTrial& p, int a, std::size_t k, auto& c, std::size_t i) {
      c[0][i] = p.u_pert_rate[k](a);
    });
  }
};

}  // namespace

// Uncompensated stage friction, Coulomb F per workspace axis with the smooth
// law f_fr = −F tanh(v / v_s) (v the stage velocity on that axis): what goes
// into the eq. 14 target, derived (sim: session_runner.cpp puts f_fr on the
// stage beside u_pert, uncompensated).
//
// Where it enters. The admittance (eq. 19-20) renders the handle from the
// force sensor; the stage also carries u_pert and f_fr. With u_ext the force
// of the handle on the hand (the sign of eq. 21), over the WHOLE trial:
//   u_ext = u_pert + f_fr − (M_adm + M_handle) ẍ − D_adm ẋ,
// while eq. 21 computed from the log has no f_fr.
// The isolation (estimation::isolate_variational, paper §3.1) is linear in
// the position it is given: Δẍ = ∫_onset^t HP(SG₃ x), Δẋ, Δx its integrals
// from onset. Write I[s] for that chain applied to a signal s as if it were
// an acceleration (SG₃ of its double integral, high-pass, ∫ from onset):
// Δẍ = I[ẍ]; and because the high-pass and d/dt commute, Δẋ = I[ẋ] and
// Δx = I[x] up to polynomials in t − t_onset of order 1 and 2 (the
// integration constants from onset): the baseline's own nuisance, projected
// at order 1 as before (Projector); friction adds no polynomial of its own.
// The person (eq. 14 on the full signals, a smooth plan term g with
// I[g] ≈ 0, as the isolation already assumes): u_ext = M_BSP ẍ + D ẋ + K x + g.
// Apply I to both relations and put them into the target of eq. 14:
//   y = u_pert − (M_adm + M_handle + M_BSP) Δẍ − D_adm Δẋ
//     = D Δẋ + K Δx + F · I[tanh(v/v_s)] + (u_pert − I[u_pert])   (mod polynomial)
// (the last term is the baseline's own; f_fr enters with −I[f_fr] = +F I[tanh]).
// So the column is I[tanh(v/v_s)] of the perturbed trial only: no unperturbed
// run and no Δv. The friction of the unperturbed movement is in both sides
// consistently — what the person felt of it is in the isolated Δx, Δẋ the
// same way (I is exact on the full signals). The earlier column
// F[tanh(v/v_s) − tanh((v − Δv)/v_s)] missed the SG smoothing (225 samples
// at 4 kHz, 56 ms: a third of the window, exactly where the steps are) and
// took the unperturbed run's sign changes from the noisy isolated Δv.
// Per axis: tanh acts per workspace axis, I is the same linear filter on each
// axis, so I commutes with the workspace→shoulder rotation R:
// column = R I[tanh(Rᵀ v / v_s)], computed here as the Δẍ that
// isolate_variational makes of the position R ∬ tanh(Rᵀ v / v_s) over the
// trial's own span and onset (the same code, not a copy of it).
// v: the logged admittance reference velocity (the stage follows the
// reference). Measured: with the backward difference of the quantised
// encoder position instead, friction 0.5 and 1 N were named in 0/20 sessions
// each (18/20 and 20/20 with the reference): the difference is noise at
// v_s = 1 mm/s. Without a reference velocity, the SG first derivative of the
// position (not measured).
std::vector<std::vector<Vector2d>> isolated_stage_friction(const estimation::SessionInfo& info, const estimation::TrialData& trial,
                                                           const estimation::PipelineSettings& pipeline, const Matrix2d& ws_to_sh) {
  const std::size_t n = trial.x_m.size();
  const double dt = 1.0 / info.sample_rate_hz;
  const Matrix2d sh_to_ws = ws_to_sh.transpose();
  std::vector<Vector2d> v_ws(n, Vector2d::Zero());
  if (trial.xd_ref_m.size() == n) {
    for (std::size_t i = 0; i < n; ++i) v_ws[i] = sh_to_ws * trial.xd_ref_m[i];
  } else if (n >= static_cast<std::size_t>(estimation::sg_window_for(pipeline, info.sample_rate_hz))) {
    // No reference velocity: the pipeline's SG first derivative of the measured
    // position (a plain difference of the quantised encoder is noise at v_s).
    const dsp::SavgolFilter rate(estimation::sg_window_for(pipeline, info.sample_rate_hz), pipeline.sg_order, 1, dt);
    std::vector<double> x(n), xd(n);
    for (int a = 0; a < 2; ++a) {
      for (std::size_t i = 0; i < n; ++i) x[i] = trial.x_m[i](a);
      rate.apply(x, xd);
      for (std::size_t i = 0; i < n; ++i) v_ws[i](a) = xd[i];
    }
    for (auto& v : v_ws) v = sh_to_ws * v;
  }
  estimation::TrialData g = trial;  // same span, onset and channels; only the position is replaced
  std::vector<std::vector<Vector2d>> out;
  out.reserve(kStageFrictionVs.size());
  for (const double vs : kStageFrictionVs) {
    Vector2d f_prev = Vector2d::Zero(), vel = Vector2d::Zero(), pos = Vector2d::Zero();
    for (std::size_t i = 0; i < n; ++i) {
      Vector2d f;
      for (int j = 0; j < 2; ++j) f(j) = std::tanh(v_ws[i](j) / vs);
      f = ws_to_sh * f;
      if (i > 0) {  // trapezoid, twice (SG₃ is exact on the integration constants)
        const Vector2d vel_next = vel + 0.5 * dt * (f_prev + f);
        pos += 0.5 * dt * (vel + vel_next);
        vel = vel_next;
      }
      f_prev = f;
      g.x_m[i] = pos;
    }
    out.push_back(estimation::isolate_variational(info, g, pipeline).dxdd);
  }
  return out;
}

namespace {

class StageFriction final : public Mechanism {
 public:
  std::string id() const override { return "stage_friction"; }
  std::string title() const override { return "stage friction not compensated: Coulomb F tanh(v / v_s) per workspace axis"; }
  std::string signature() const override {
    return "residual follows the isolated tanh(v / v_s) of the stage velocity: smoothed steps where it changes sign, "
           "mostly on the lateral axis of a reach";
  }
  std::string not_applicable(const Dataset& d) const override { return planar_only(d); }
  std::vector<ParamInfo> shape_params() const override { return {{"v_s", "m/s", kStageFrictionVs.front(), kStageFrictionVs.back()}}; }
  // Linear-guide stages: 0.5-5 N breakaway; 10 N bounds a badly adjusted rig.
  std::vector<ParamInfo> gains() const override { return {{"F_coulomb", "N", 0.0, 10.0}}; }
  int main_param() const override { return 1; }
  std::vector<std::vector<double>> grid(const Dataset&) const override {
    std::vector<std::vector<double>> g;
    for (double v : kStageFrictionVs) g.push_back({v});
    return g;
  }
  // The isolated series prepared per trial (PlanarTrial::friction_iso), one per v_s of the grid.
  Columns columns(const Dataset& d, std::span<const double> s) const override {
    std::size_t iv = kStageFrictionVs.size();
    for (std::size_t i = 0; i < kStageFrictionVs.size(); ++i)
      if (std::fabs(kStageFrictionVs[i] - s[0]) <= 1e-9 * kStageFrictionVs[i]) iv = i;
    if (iv == kStageFrictionVs.size()) throw std::invalid_argument("stage_friction: v_s " + num(s[0]) + " is not on the grid");
    for (const auto& p : d.planar)
      if (p.friction_iso.size() != kStageFrictionVs.size() || p.friction_iso[iv].size() != p.dx.size())
        throw std::invalid_argument("stage_friction: trial " + std::to_string(p.trial) + " has no isolated friction series");
    return planar_columns(d, 1, [iv](const PlanarTrial& p, int a, std::size_t k, auto& c, std::size_t i) {
      c[0][i] = p.friction_iso[iv][k](a);
    });
  }
};

// Handle mass different from the configured one (eq. 19-21 use the session's
// M_handle): eq. 21 − true Δu_ext = ΔM Δẍ (both axes, isotropic).
class HandleMass final : public Mechanism {
 public:
  std::string id() const override { return "handle_mass"; }
  std::string title() const override { return "handle mass different from the configured one: ΔM Δẍ"; }
  std::string signature() const override { return "residual proportional to Δẍ on both axes, isotropic"; }
  std::string not_applicable(const Dataset& d) const override { return planar_only(d); }
  std::vector<ParamInfo> gains() const override { return {{"handle_extra", "kg", -1.0, 1.0}}; }
  int main_param() const override { return 0; }
  std::vector<std::vector<Vector2d>> model_correction(const Dataset& d, std::span<const double>, std::span<const double> g,
                                                      const Matrix2d& dm, const Matrix2d& km) const override {
    LinearExtension e;
    e.mass_kg = (g.empty() ? 0.0 : g[0]) * Matrix2d::Identity();
    return simulate_extension(d, dm, km, [&](const PlanarTrial&) { return e; });
  }
  Columns columns(const Dataset& d, std::span<const double>) const override {
    return planar_columns(d, 1, [](const PlanarTrial& p, int a, std::size_t k, auto& c, std::size_t i) {
      c[0][i] = p.dxdd[k](a);
    });
  }
};

// Segment inertia M_BSP (eq. 16, from anthropometric tables) wrong by a
// factor: M_true = (1 + s) M_BSP, so the residual is s M_BSP Δẍ.
class WrongMbsp final : public Mechanism {
 public:
  std::string id() const override { return "wrong_segment_inertia"; }
  std::string title() const override { return "segment inertia M_BSP (eq. 16) off by a factor (1 + s)"; }
  std::string signature() const override { return "residual proportional to M_BSP Δẍ (anisotropic, follows the arm's posture)"; }
  std::string not_applicable(const Dataset& d) const override { return planar_only(d); }
  // Regression tables predict segment masses and inertias to ~10-30 % of a person's.
  std::vector<ParamInfo> gains() const override { return {{"mbsp_error", "1", -0.5, 0.5}}; }
  int main_param() const override { return 0; }
  std::vector<std::vector<Vector2d>> model_correction(const Dataset& d, std::span<const double>, std::span<const double> g,
                                                      const Matrix2d& dm, const Matrix2d& km) const override {
    return simulate_extension(d, dm, km, [&](const PlanarTrial& p) {
      LinearExtension e;
      e.mass_kg = (g.empty() ? 0.0 : g[0]) * p.m_bsp;
      return e;
    });
  }
  Columns columns(const Dataset& d, std::span<const double>) const override {
    return planar_columns(d, 1, [](const PlanarTrial& p, int a, std::size_t k, auto& c, std::size_t i) {
      c[0][i] = (p.m_bsp * p.dxdd[k])(a);
    });
  }
};

}  // namespace

DelayedProjection delayed_projection(const Dataset& d, double tau_s) {
  // Normal equations of Δx(t − τ) and Δẋ(t − τ) on [Δx, Δẋ], both axes of
  // every planar trial pooled, Δ = 0 before onset.
  const auto lag = static_cast<std::size_t>(std::max(0L, std::lround(tau_s / d.dt_s)));
  Eigen::Matrix2d g = Eigen::Matrix2d::Zero();
  Eigen::Vector2d rx = Eigen::Vector2d::Zero(), rv = Eigen::Vector2d::Zero();
  for (const auto& p : d.planar)
    for (std::size_t k = 0; k < p.dx.size() && k < p.dxd.size(); ++k)
      for (int a = 0; a < 2; ++a) {
        const Eigen::Vector2d z(p.dx[k](a), p.dxd[k](a));
        g += z * z.transpose();
        if (k >= lag) {
          rx += z * p.dx[k - lag](a);
          rv += z * p.dxd[k - lag](a);
        }
      }
  DelayedProjection out;
  if (!(g.determinant() > 0)) return out;
  const auto gram = g.ldlt();
  const Eigen::Vector2d cx = gram.solve(rx), cv = gram.solve(rv);
  out.a_x = cx(0);
  out.b_x = cx(1);
  out.a_v = cv(0);
  out.b_v = cv(1);
  return out;
}

namespace {

// Feedback on the deviation as a delayed copy of the arm's own impedance:
// g [D Δẋ(t − τ) + K Δx(t − τ)] (before onset Δ = 0). Two entries of the
// library share it and differ in their delay range (DelayedCopySpec):
// - the short-latency stretch reflex (20-60 ms). It is driven by the same
//   muscle-spindle signals whose intrinsic stiffness and damping it scales
//   (the neuromechanical model's short-latency pathway, §4), so one gain and
//   one delay describe it;
// - feedback earlier than the model assumes (50-150 ms): the paper's window
//   ends at T_est = δ_v,dev because voluntary feedback is taken to start
//   there (§2, eq. 4-6, δ_v ≈ 115 ms + T_dev 35 ms); a long-latency reflex
//   or an early voluntary reaction on the deviation inside the window is a
//   feedback delay shorter than that (the neuromechanical model's PD
//   feedback on the tracking error at δ_s = 60 ms, §4, is one).
// Why not a free D_r (4) and K_r (3): within T_est a delayed term equals D,
// K to first order (Δx(t − τ) ≈ Δx − τ Δẋ), and seven free gains cost so
// much power that a realistic reflex (g ≈ 0.5) sat two orders of magnitude
// below their detection limit (docs/diagnosis.md, "Detection limits"); one
// gain along the known direction leaves only the curvature of the response
// to tell the delay apart, and uses all of it.
// The gain parameter is the copy's share of the apparent impedance,
// g_app = g / (1 + g) (to first order K_app = (1 + g) K): bounded, and what
// the equation-error column (a delayed copy of the session's apparent D, K,
// Dataset::planar_ref_*) estimates. The likelihood check's model-based
// correction copies the fit's own, intrinsic D, K with g = g_app / (1 − g_app),
// which makes D, K a fixed point of the fit (next_reference): copying the
// apparent D, K fixes the ratio D : K of the delayed column to the baseline's,
// which a short pulse moves far from the intrinsic one (50 ms, 20 N, reflex
// 1.0: baseline K11 4.7 × intrinsic; docs/diagnosis.md, "Pulse").
// A third entry makes the reflex direction dependent (one_sided): one
// muscle group's reflex, along its line w and only while a deviation along w
// stretches it, g w max(0, wᵀ[D Δẋ + K Δx](t − τ)) (docs/diagnosis.md,
// "Direction-dependent reflex").
struct DelayedCopySpec {
  const char* id;
  const char* title;
  const char* signature;
  const char* derived;          // the intrinsic gain's name in the report
  double lo_s, hi_s, step_s;    // the equation-error delay grid
  std::vector<double> profile;  // the delays the likelihood check profiles itself
  bool one_sided = false;       // a second shape parameter: the direction ψ of w
  // Upper plausible bound of gain_apparent = g/(1 + g) (below).
  double gain_apparent_hi = 0.6;
};

// The one-sided copy's direction grids: the equation error's 16 directions,
// 22.5° apart; the likelihood check's 8, 45° apart.
constexpr int kDirections = 16, kProfileDirections = 8;
// w of a one-sided copy's shape (delay, direction ψ).
Vector2d direction_of(std::span<const double> shape) {
  const double psi = shape.size() > 1 ? shape[1] : 0.0;
  return {std::cos(psi), std::sin(psi)};
}

class PlanarReflex final : public Mechanism {
 public:
  explicit PlanarReflex(DelayedCopySpec spec) : spec_(std::move(spec)) {}
  std::string id() const override { return spec_.id; }
  std::string title() const override { return spec_.title; }
  std::string signature() const override { return spec_.signature; }
  std::string not_applicable(const Dataset& d) const override {
    if (auto why = planar_only(d); !why.empty()) return why;
    if (d.planar_ref_k.isZero()) return "no baseline D, K to copy";
    return {};
  }
  // Gain: a reflex adds up to about the intrinsic impedance again (Kearney et
  // al. 1997: reflex torque comparable to intrinsic at the ankle), so
  // g/(1+g) up to about 0.5 (0.6 for margin); down to −0.2 stays plausible
  // (noise around a small reflex). The same bounds for the early feedback:
  // the neuromechanical arm's feedback doubles its apparent K within the
  // window (docs/diagnosis.md, "Early feedback"), a share of 0.5.
  // The direction is periodic: its range [−π, 2π] brackets the grid
  // [0, 2π) so that no direction is "on the edge".
  std::vector<ParamInfo> shape_params() const override {
    if (spec_.one_sided) return {{"delay", "s", spec_.lo_s, spec_.hi_s}, {"direction", "rad", -std::numbers::pi, 2 * std::numbers::pi}};
    return {{"delay", "s", spec_.lo_s, spec_.hi_s}};
  }
  // One muscle group's gain (one_sided) is against the intrinsic impedance
  // along its line w, which along the arm's compliant axis is a fifth of the
  // stiff axis's (Table 1's K: 65 against 359 N/m), so the same reflex force
  // is a larger g there: up to 0.7 (g 2.3). With 0.6, hidden 1.5 (g_app 0.6)
  // sat on the bound and 4 of 8 sessions came out implausible once the
  // amplitude profile reached the optimum (seeds 5000-5007; before, the
  // profile stopped at g_app 0.5).
  std::vector<ParamInfo> gains() const override { return {{"gain_apparent", "1", -0.2, spec_.gain_apparent_hi}}; }
  int main_param() const override { return 0; }
  DerivedGain derived_gain() const override {
    return {{spec_.derived, "1", -0.2, spec_.gain_apparent_hi / (1.0 - spec_.gain_apparent_hi)}, &reflex_intrinsic_gain};
  }
  // The equation-error delay and gain are noise at realistic gains (its
  // detection limit there is above the intrinsic impedance), so the
  // likelihood profiles a coarse delay grid inside the search range, along a
  // fixed direction: gain_apparent 0.25 per unit amplitude (the profile's
  // [−2, 3] spans the physiological range).
  // The one-sided copy profiles 8 directions itself at the middle delay,
  // then the other two delays at the best direction, with g ≥ 0: a group
  // along w with gain g and one along −w with gain −g differ only by a
  // symmetric copy, which D, K absorb to first order, so with
  // negative gains allowed opposite directions fit alike (hidden
  // directional reflex 1.0 at 51°, seed 5000: LR 14 at 135° with g < 0
  // against 11 at 45°, where g came out at the truth). The equation error's
  // direction, picked with either sign, was 180° there.
  LikelihoodPlan likelihood_plan(const Dataset&, std::span<const double>) const override {
    LikelihoodPlan p;
    p.gain_per_unit = 0.25;
    if (!spec_.one_sided) {
      for (const double tau : spec_.profile) p.shapes.push_back({tau});
      return p;
    }
    p.alpha_min = 0.0;
    for (int j = 0; j < kProfileDirections; ++j) p.shapes.push_back({spec_.profile[1], 2 * std::numbers::pi * j / kProfileDirections});
    p.then_first = {spec_.profile[0], spec_.profile[2]};
    p.second_step = std::numbers::pi / kProfileDirections;  // 22.5°, half the grid
    return p;
  }
  std::vector<std::vector<Vector2d>> model_correction(const Dataset& d, std::span<const double> s, std::span<const double> g,
                                                      const Matrix2d& dm, const Matrix2d& km) const override {
    LinearExtension e;
    const double gain = intrinsic_gain(g);
    e.damping_delayed_nspm = gain * dm;
    e.stiffness_delayed_npm = gain * km;
    e.delay_s = s.empty() ? spec_.profile.front() : s[0];
    if (spec_.one_sided) {  // gated on the unscaled copy (a negative gain acts on the same side)
      e.damping_delayed_nspm = dm;
      e.stiffness_delayed_npm = km;
      e.delayed_gain = gain;
      e.delayed_one_sided_along = direction_of(s);
    }
    return simulate_extension(d, dm, km, [&](const PlanarTrial&) { return e; });
  }
  // One Newton step to the fixed point D, K = fit(copy of D, K). Within the
  // window the delayed signals are, in least squares over the session's
  // trials, Δx(t − τ) ≈ a_x Δx + b_x Δẋ and Δẋ(t − τ) ≈ a_v Δx + b_v Δẋ
  // (delayed_projection). The fit absorbs what the copy at (D0, K0) lacks,
  // g [(D − D0) Δẋ + (K − K0) Δx](t − τ), so it returns
  //   K1 = K + g a_x (K − K0) + g a_v (D − D0),
  //   D1 = D + g b_v (D − D0) + g b_x (K − K0),
  // solved here for the person's D, K (exact when the fit is affine in the
  // copy). For τ short against the response, a_x = b_v = 1, b_x = −τ,
  // a_v = 0 (first order): K = (K1 + g K0)/(1 + g). Under the paper's pulse
  // it is far off (hidden session, seed 1): at 30 ms a_x 0.77, b_x −0.015 s,
  // a_v 14 1/s, b_v 0.04; at 60 ms a_x 0.31; at 90 ms 0.05. Stepping with
  // the first order overshot: hidden feedback 1.0 fitted at 60 ms, corrected
  // K11 −20 N/m against an intrinsic 107 (docs/diagnosis.md, "Early feedback").
  // The one-sided copy acts through P = f w wᵀ instead of the identity, f the
  // share of the copy's energy along w that falls on stretch (wᵀ c > 0) over
  // the session's trials at (D0, K0): the fit absorbs P g [...], so
  //   [[I + g a_x P, g a_v P], [g b_x P, I + g b_v P]] [K; D]
  //     = [K1 + g P (a_x K0 + a_v D0); D1 + g P (b_x K0 + b_v D0)].
  void next_reference(const Dataset& d, std::span<const double> s, std::span<const double> g, const Matrix2d& d0, const Matrix2d& k0,
                      Matrix2d& d1, Matrix2d& k1) const override {
    const double gain = intrinsic_gain(g), tau = s.empty() ? spec_.profile.front() : s[0];
    const auto pr = delayed_projection(d, tau);
    if (!spec_.one_sided) {
      // P = I: [[1 + g a_x, g a_v], [g b_x, 1 + g b_v]] [K; D] = [...], element-wise.
      const double m11 = 1 + gain * pr.a_x, m12 = gain * pr.a_v, m21 = gain * pr.b_x, m22 = 1 + gain * pr.b_v;
      const double det = m11 * m22 - m12 * m21;
      if (!(std::fabs(det) > 1e-9)) return;
      const Matrix2d rk = k1 + gain * pr.a_x * k0 + gain * pr.a_v * d0, rd = d1 + gain * pr.b_v * d0 + gain * pr.b_x * k0;
      k1 = (m22 * rk - m12 * rd) / det;
      d1 = (m11 * rd - m21 * rk) / det;
      return;
    }
    const Vector2d w = direction_of(s);
    const Matrix2d p = stretch_share(d, tau, w, d0, k0) * w * w.transpose();
    Eigen::Matrix4d a;
    a << Matrix2d::Identity() + gain * pr.a_x * p, gain * pr.a_v * p, gain * pr.b_x * p, Matrix2d::Identity() + gain * pr.b_v * p;
    Eigen::Matrix<double, 4, 2> rhs;
    rhs << k1 + gain * p * (pr.a_x * k0 + pr.a_v * d0), d1 + gain * p * (pr.b_x * k0 + pr.b_v * d0);
    const Eigen::FullPivLU<Eigen::Matrix4d> lu(a);
    if (!lu.isInvertible()) return;
    const Eigen::Matrix<double, 4, 2> kd = lu.solve(rhs);
    k1 = kd.topRows<2>();
    d1 = kd.bottomRows<2>();
  }
  // Σ over stretch samples of (wᵀ c)² / Σ over all of (wᵀ c)², c = D0 Δẋ + K0 Δx delayed by τ.
  static double stretch_share(const Dataset& d, double tau_s, const Vector2d& w, const Matrix2d& d0, const Matrix2d& k0) {
    const auto lag = static_cast<std::size_t>(std::max(0L, std::lround(tau_s / d.dt_s)));
    double on = 0, all = 0;
    for (const auto& q : d.planar)
      for (std::size_t k = lag; k < q.dx.size() && k < q.dxd.size(); ++k) {
        const double v = w.dot(d0 * q.dxd[k - lag] + k0 * q.dx[k - lag]);
        all += v * v;
        if (v > 0) on += v * v;
      }
    return all > 0 ? on / all : 0.5;
  }
  static double intrinsic_gain(std::span<const double> g) { return reflex_intrinsic_gain(g.empty() ? 0.0 : g[0]); }
  std::vector<std::vector<double>> grid(const Dataset& d) const override {
    std::vector<std::vector<double>> g;
    const auto step = std::max<long>(1, std::lround(spec_.step_s / d.dt_s));
    for (long i = std::lround(spec_.lo_s / d.dt_s); i <= std::lround(spec_.hi_s / d.dt_s); i += step) {
      const double tau = static_cast<double>(i) * d.dt_s;
      if (!spec_.one_sided) {
        g.push_back({tau});
        continue;
      }
      for (int j = 0; j < kDirections; ++j) g.push_back({tau, 2 * std::numbers::pi * j / kDirections});
    }
    return g;
  }
  Columns columns(const Dataset& d, std::span<const double> s) const override {
    const auto lag = static_cast<std::size_t>(std::lround(s[0] / d.dt_s));
    const Matrix2d dr = d.planar_ref_d, kr = d.planar_ref_k;
    const Vector2d w = spec_.one_sided ? direction_of(s) : Vector2d::Zero();
    return planar_columns(d, 1, [lag, dr, kr, w](const PlanarTrial& p, int a, std::size_t k, auto& c, std::size_t i) {
      if (k < lag) return;
      const Vector2d copy = dr * p.dxd[k - lag] + kr * p.dx[k - lag];
      c[0][i] = w.isZero() ? copy(a) : w(a) * std::max(0.0, w.dot(copy));
    });
  }

 private:
  DelayedCopySpec spec_;
};

// Shoulder/elbow short-latency stretch reflex: EMG latency 20-45 ms, force
// ~10 ms later (Lee & Tatton 1975; Pruszynski & Scott 2012): 20-60 ms. A
// shorter delay makes the delayed column a finite difference of the
// baseline's that fits any smooth model error. The likelihood profile starts
// at 22 ms, inside the bound (as the early feedback's stays 10 ms inside its
// range): from 25 ms a delay near 25 ms had no neighbour below for the
// parabolic steps and was named on the grid's edge (hidden reflex 1.0, 50 ms
// pulse: 3/10 at 25.0 ms, interval open below); from 20 ms a weak reflex's
// flat profile put its best on the bound, implausible (reflex 0.25 named
// 6/10). docs/diagnosis.md, "The profile from 22 ms".
DelayedCopySpec short_latency_reflex_spec() {
  return {"short_latency_reflex",
          "short-latency reflex: g [D Δẋ(t - tau) + K Δx(t - tau)], a delayed copy of the impedance",
          "residual along D Δẋ + K Δx delayed by 20-60 ms; none in the first tau of the window, growing after",
          "reflex_gain",
          0.020,
          0.060,
          0.001,
          {0.022, 0.025, 0.030, 0.035, 0.040, 0.050}};
}

// Long-latency reflex 50-100 ms (Pruszynski & Scott 2012), voluntary
// reactions from ~100-120 ms (the paper's δ_v, §2): searched over 50-150 ms,
// profiled at 60-130 ms, above the reflex's profile so the two never
// profile the same delay (a best delay at the search range's edge makes a
// fit implausible, and 60 ms, the neuromechanical arm's δ_s, must not be
// one). Beyond 130 ms the copy acts for less than 20 ms of the 150 ms
// window. The equation-error grid steps 2 ms (the likelihood check does not
// use its pick).
DelayedCopySpec early_feedback_spec() {
  return {"early_feedback",
          "feedback earlier than T_est (long-latency reflex or early voluntary reaction): g [D Δẋ(t - tau) + K Δx(t - tau)]",
          "residual along D Δẋ + K Δx delayed by 50-150 ms: none before tau, then growing to the window's end",
          "feedback_gain",
          0.050,
          0.150,
          0.002,
          {0.060, 0.075, 0.090, 0.110, 0.130}};
}

// The short-latency reflex of one muscle group: its delays, and a direction.
// The equation-error grid steps 5 ms in the delay (16 directions each); the
// likelihood check profiles its 8 directions at 35 ms, then 25 and 50 ms at
// the best direction (10 profiles; the parabolic steps refine the delay).
DelayedCopySpec directional_reflex_spec() {
  return {"directional_reflex",
          "direction-dependent short-latency reflex: g w max(0, w' [D Δẋ + K Δx](t - tau)), one muscle group along w, only when stretched",
          "residual along D Δẋ + K Δx delayed by 20-60 ms for pushes along w only: opposite pushes meet different impedances, which "
          "no symmetric K fits",
          "reflex_gain",
          0.020,
          0.060,
          0.005,
          {0.025, 0.035, 0.050},
          true,
          0.7};
}

// Stiffness changing linearly within the window: K(t) = K + K' (t/T − 1/2).
class TimeVaryingStiffness final : public Mechanism {
 public:
  std::string id() const override { return "time_varying_stiffness"; }
  std::string title() const override { return "stiffness changing within the window: K + K_slope (t/T_est - 1/2)"; }
  std::string signature() const override { return "the baseline's K fitted on early and late parts of the window differ"; }
  std::string not_applicable(const Dataset& d) const override { return planar_only(d); }
  std::vector<ParamInfo> gains() const override {
    return {{"Kslope11", "N/m", -1000, 1000}, {"Kslope12", "N/m", -1000, 1000}, {"Kslope22", "N/m", -1000, 1000}};
  }
  int main_param() const override { return 0; }
  Columns columns(const Dataset& d, std::span<const double>) const override {
    const double dt = d.dt_s;
    return planar_columns(d, 3, [dt](const PlanarTrial& p, int a, std::size_t k, auto& c, std::size_t i) {
      const double T = static_cast<double>(p.dx.size() - 1) * dt;
      const double w = static_cast<double>(k) * dt / T - 0.5;
      double row[7];
      baseline_row(a, p.dxd[k], p.dx[k], row);
      c[0][i] = w * row[4];
      c[1][i] = w * row[5];
      c[2][i] = w * row[6];
    });
  }
};

}  // namespace

double reflex_intrinsic_gain(double share) {
  share = std::min(share, 0.9);
  return share / (1 - share);
}

std::vector<std::unique_ptr<Mechanism>> planar_library(int nuisance_order, bool with_time_varying, bool with_directional_reflex) {
  auto v = planar_library(with_time_varying, with_directional_reflex);
  if (nuisance_order < 0) return v;
  for (auto& m : v) m = std::make_unique<Projected>(std::move(m), nuisance_order);
  return v;
}

std::vector<std::unique_ptr<Mechanism>> planar_library(bool with_time_varying, bool with_directional_reflex) {
  std::vector<std::unique_ptr<Mechanism>> v;
  v.push_back(std::make_unique<PlanarReflex>(short_latency_reflex_spec()));
  v.push_back(std::make_unique<PlanarReflex>(early_feedback_spec()));
  v.push_back(std::make_unique<Curl>());
  v.push_back(std::make_unique<ActuationDelay>());
  v.push_back(std::make_unique<StageFriction>());
  v.push_back(std::make_unique<HandleMass>());
  v.push_back(std::make_unique<WrongMbsp>());
  v.push_back(make_force_sensor_lag());
  // TimeVaryingStiffness is not in the default library: in a 150 ms window its
  // columns (t-weighted Δx) are confounded with Δẍ (handle mass, M_BSP) and
  // the delayed reflex; on hidden handle-mass sessions it was accepted in
  // their place (docs/diagnosis.md). Available with with_time_varying.
  if (with_time_varying) v.push_back(std::make_unique<TimeVaryingStiffness>());
  // The direction-dependent reflex likewise (PlanarOptions::directional_reflex).
  if (with_directional_reflex) v.push_back(std::make_unique<PlanarReflex>(directional_reflex_spec()));
  return v;
}

namespace {
PlanarImpedance impedance_from(const std::vector<ParamEstimate>& ps) {
  auto get = [&](const char* n) {
    for (const auto& p : ps)
      if (p.name == n) return p.est.value;
    return 0.0;
  };
  PlanarImpedance z;
  z.d << get("D11"), get("D12"), get("D21"), get("D22");
  z.k << get("K11"), get("K12"), get("K12"), get("K22");
  return z;
}
}  // namespace

PlanarImpedance baseline_impedance(const Diagnosis& dg) { return impedance_from(dg.baseline_params); }

PlanarImpedance final_impedance(const Diagnosis& dg) {
  PlanarImpedance z = impedance_from(dg.final_params);
  if (const auto* c = dg.find_final("curl_c"); c && std::find(dg.accepted.begin(), dg.accepted.end(), "curl_stiffness") != dg.accepted.end()) {
    z.k(0, 1) += c->est.value;
    z.k(1, 0) -= c->est.value;
  }
  return z;
}

std::vector<WindowMisfit> window_misfit(const Dataset& d, const Diagnosis& dg, const std::vector<std::unique_ptr<Mechanism>>& lib,
                                        const std::vector<double>& edges_s) {
  // The extended model's columns (accepted order), refitted on all data.
  std::vector<Columns> cols;
  for (std::size_t a = 0; a < dg.accepted.size(); ++a)
    for (const auto& m : lib)
      if (m->id() == dg.accepted[a]) cols.push_back(m->columns(d, dg.accepted_settings[a]));
  std::vector<const Columns*> ext;
  for (const auto& c : cols) ext.push_back(&c);
  const auto f0 = fit_full(d, {});
  const auto f1 = fit_full(d, ext);
  std::vector<WindowMisfit> out;
  for (std::size_t w = 0; w + 1 < edges_s.size(); ++w) {
    WindowMisfit m;
    m.t0_s = edges_s[w];
    m.t1_s = edges_s[w + 1];
    double yy = 0, r0 = 0, r1 = 0, n = 0;
    double s0[2] = {0, 0}, s1[2] = {0, 0}, na[2] = {0, 0};
    for (std::size_t s = 0; s < d.segments.size(); ++s) {
      const auto& g = d.segments[s];
      for (std::size_t k = g.first; k < g.last; ++k) {
        const double t = static_cast<double>(k) * d.dt_s;
        if (t < m.t0_s || t >= m.t1_s) continue;
        double p0 = 0, p1 = 0;
        for (std::size_t j = 0; j < g.base.size(); ++j) {
          p0 += f0.theta(static_cast<Eigen::Index>(j)) * g.base[j][k];
          p1 += f1.theta(static_cast<Eigen::Index>(j)) * g.base[j][k];
        }
        Eigen::Index c = static_cast<Eigen::Index>(g.base.size());
        for (const auto& cc : cols)
          for (const auto& col : cc[s]) p1 += f1.theta(c++) * col[k];
        const double e0 = g.y[k] - p0, e1 = g.y[k] - p1;
        yy += g.y[k] * g.y[k];
        r0 += e0 * e0;
        r1 += e1 * e1;
        n += 1;
        const auto ax = static_cast<std::size_t>(std::max(0, g.axis));
        s0[ax] += e0;
        s1[ax] += e1;
        na[ax] += 1;
      }
    }
    if (n > 0) {
      m.target_rms = std::sqrt(yy / n);
      m.resid_before = std::sqrt(r0 / n);
      m.resid_after = std::sqrt(r1 / n);
      for (int a = 0; a < 2; ++a) {
        m.mean_before[a] = na[a] > 0 ? s0[a] / na[a] : 0.0;
        m.mean_after[a] = na[a] > 0 ? s1[a] / na[a] : 0.0;
      }
    }
    out.push_back(m);
  }
  return out;
}

SensorDisagreement sensor_disagreement(const Dataset& d) {
  SensorDisagreement out;
  std::vector<double> e, du, urate, fr, acc;
  for (const auto& p : d.planar)
    for (std::size_t k = 0; k < p.dx.size(); ++k)
      for (int a = 0; a < 2; ++a) {
        e.push_back(p.du_ext_adm[k](a) - p.du_ext_force[k](a));
        du.push_back(p.du_ext_adm[k](a));
        urate.push_back(p.u_pert_rate[k](a));
        acc.push_back(p.dxdd[k](a));
        // Friction column at v_s = 1 mm/s (the shape is refined by the mechanism).
        const Matrix2d sh_to_ws = p.ws_to_sh.transpose();
        const Vector2d v = sh_to_ws * p.xd_stage[k], dv = sh_to_ws * p.dxd[k];
        Vector2d f;
        for (int j = 0; j < 2; ++j) f(j) = std::tanh(v(j) / 0.001) - std::tanh((v(j) - dv(j)) / 0.001);
        fr.push_back((p.ws_to_sh * f)(a));
      }
  auto rms = [](const std::vector<double>& x) {
    double s = 0;
    for (double v : x) s += v * v;
    return x.empty() ? 0.0 : std::sqrt(s / static_cast<double>(x.size()));
  };
  auto corr = [](const std::vector<double>& x, const std::vector<double>& y) {
    const double n = static_cast<double>(x.size());
    double mx = 0, my = 0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      mx += x[i];
      my += y[i];
    }
    mx /= n;
    my /= n;
    double sxy = 0, sxx = 0, syy = 0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      sxy += (x[i] - mx) * (y[i] - my);
      sxx += (x[i] - mx) * (x[i] - mx);
      syy += (y[i] - my) * (y[i] - my);
    }
    return sxx > 0 && syy > 0 ? sxy / std::sqrt(sxx * syy) : 0.0;
  };
  const double r_du = rms(du);
  out.rms_share = r_du > 0 ? rms(e) / r_du : 0.0;
  out.rho = {{"actuation_delay (u̇_pert)", corr(e, urate)}, {"stage_friction (Δtanh, v_s 1 mm/s)", corr(e, fr)}, {"handle_mass (Δẍ)", corr(e, acc)}};
  return out;
}

}  // namespace manip::diagnosis

namespace manip::diagnosis {

std::vector<double> default_window_edges(double t_est_s) {
  std::vector<double> e = {0.0, 0.035};
  if (t_est_s > 0.035) e.push_back(std::min(t_est_s, 0.150));
  if (t_est_s > 0.150) e.push_back(std::min(t_est_s, 0.400));
  if (t_est_s > 0.400) e.push_back(t_est_s);
  e.back() += 1e-9;  // include the last sample
  return e;
}

namespace {
std::string mat(const Eigen::Matrix2d& m) {
  return "[" + g4(m(0, 0)) + " " + g4(m(0, 1)) + "; " + g4(m(1, 0)) + " " + g4(m(1, 1)) + "]";
}
nlohmann::json jmat(const Eigen::Matrix2d& m) { return {m(0, 0), m(0, 1), m(1, 0), m(1, 1)}; }
}  // namespace

PlanarReport planar_report(const PlanarPrepared& prep, const Diagnosis& dg, const std::vector<std::unique_ptr<Mechanism>>& lib) {
  PlanarReport r;
  std::ostringstream o;
  const auto z0 = baseline_impedance(dg), z1 = final_impedance(dg);
  o << "\nImpedance (shoulder frame; D [N s/m], K [N/m]; equation error on the isolated signals of eq. 21, M_BSP fixed):\n";
  o << "  baseline:                      D " << mat(z0.d) << "  K " << mat(z0.k) << "\n";
  if (dg.misfit_found()) o << "  after modelling the cause(s):  D " << mat(z1.d) << "  K " << mat(z1.k) << "  (curl included in K)\n";
  if (prep.pem.available)
    o << "  estimator's default (" << prep.pem.method << ", its noise model, no extension): D " << mat(prep.pem.d) << "  K " << mat(prep.pem.k) << "\n";
  else if (!prep.pem.error.empty())
    o << "  estimator's default method: not available (" << prep.pem.error << ")\n";
  if (dg.misfit_found() && prep.pem_extended.available)
    o << "  default refitted with the extension (u_pert corrected by the accepted terms, their gains from above): D " << mat(prep.pem_extended.d)
      << "  K " << mat(prep.pem_extended.k) << "\n";
  if (dg.misfit_found() && prep.refined.available) {
    o << "  default refitted with the extension's amplitude refined by its likelihood (gains x " << g4(prep.refined.alpha)
      << "; -log L " << g4(prep.refined.nll_baseline) << " without, " << g4(prep.refined.nll_alpha1) << " at x1, " << g4(prep.refined.nll_best)
      << " at the optimum): D " << mat(prep.refined.fit.d) << "  K " << mat(prep.refined.fit.k) << "   <- the corrected estimate\n";
    for (const auto& a : dg.accepted)
      for (const auto& p : dg.final_params)
        if (p.has_bounds && !p.shape && std::find_if(lib.begin(), lib.end(), [&](const auto& m) {
              if (m->id() != a) return false;
              for (const auto& gi : m->gains())
                if (gi.name == p.name) return true;
              return false;
            }) != lib.end())
          o << "    " << a << ": " << p.name << " = " << g4(p.est.value * prep.refined.alpha) << " " << p.unit << " (refined by the likelihood)\n";
  }
  const auto edges = default_window_edges(prep.t_est_s);
  const auto wm = window_misfit(prep.data, dg, lib, edges);
  o << "\nMisfit per time window after onset (full-data fits; RMS over both axes; mean residual per axis):\n";
  o << "  window [ms]   target RMS [N]   baseline resid RMS (share)   mean x1, x2 [N]";
  if (dg.misfit_found()) o << "   extended resid RMS (share)   mean x1, x2 [N]";
  o << "\n";
  nlohmann::json jw = nlohmann::json::array();
  for (const auto& w : wm) {
    char b[400];
    std::snprintf(b, sizeof b, "  %3.0f-%3.0f       %-16.4g %-10.4g (%5.1f %%)          %+.3g, %+.3g", 1000 * w.t0_s, 1000 * w.t1_s, w.target_rms,
                  w.resid_before, w.target_rms > 0 ? 100 * w.resid_before / w.target_rms : 0.0, w.mean_before[0], w.mean_before[1]);
    o << b;
    if (dg.misfit_found()) {
      std::snprintf(b, sizeof b, "       %-10.4g (%5.1f %%)            %+.3g, %+.3g", w.resid_after,
                    w.target_rms > 0 ? 100 * w.resid_after / w.target_rms : 0.0, w.mean_after[0], w.mean_after[1]);
      o << b;
    }
    o << "\n";
    jw.push_back({{"t0_s", w.t0_s}, {"t1_s", w.t1_s}, {"target_rms_n", w.target_rms}, {"resid_rms_before_n", w.resid_before},
                  {"resid_rms_after_n", w.resid_after}, {"mean_before_n", {w.mean_before[0], w.mean_before[1]}},
                  {"mean_after_n", {w.mean_after[0], w.mean_after[1]}}});
  }
  const auto sd = sensor_disagreement(prep.data);
  o << "\nEq. 21 vs the force sensor: disagreement RMS " << g4(100 * sd.rms_share)
    << " % of Δu_ext's RMS (an ideal admittance: 0.4-1.8 %); its correlation with apparatus signatures:";
  nlohmann::json jr = nlohmann::json::object();
  for (const auto& [n, v] : sd.rho) {
    o << " " << n << " " << g4(v) << ";";
    jr[n] = v;
  }
  o << "\n  (apparatus mechanisms between the logged force and the handle make the two routes disagree; person-side ones do not)\n";
  const auto& sdl = prep.sensor_delay;
  nlohmann::json jd = {{"available", sdl.available}};
  if (sdl.available && sdl.explained_share >= kSensorDelayMinShare) {
    o << "  actuation delay read from the force sensor: " << g4(1e3 * sdl.tau_s) << " ms [" << g4(1e3 * sdl.lo_s) << ", " << g4(1e3 * sdl.hi_s)
      << "] (95 % bootstrap over " << sdl.trials << " trials; the disagreement as u_pert − I[u_pert(t − tau)], " << g4(100 * sdl.explained_share)
      << " % of it explained";
    if (sdl.tracking_share > 0.0) o << ", with the tracking term below";
    if (sdl.friction_n != 0.0) o << ", with stage friction " << g4(sdl.friction_n) << " N at v_s " << g4(1e3 * sdl.friction_vs_mps) << " mm/s";
    o << "; an ideal admittance, as manip_sim simulates it, reads 0.03 ms short: docs/diagnosis.md)\n";
  } else if (sdl.available) {
    o << "  actuation delay read from the force sensor: none: the disagreement is not a delayed command (the best delay, "
      << g4(1e3 * sdl.tau_s) << " ms, explains " << g4(100 * sdl.explained_share) << " % of it; a reading needs "
      << g4(100 * kSensorDelayMinShare) << " %)\n";
  }
  if (sdl.available) {
    jd.update({{"readable", sdl.explained_share >= kSensorDelayMinShare},
               {"tracking_coef", sdl.tracking_coef},
               {"tracking_share", sdl.tracking_share},
               {"tau_s", sdl.tau_s},
               {"tau_ci95_s", {sdl.lo_s, sdl.hi_s}},
               {"explained_share", sdl.explained_share},
               {"b_ddx_kg", sdl.mass_kg},
               {"friction_n", sdl.friction_n},
               {"friction_vs_mps", sdl.friction_vs_mps},
               {"trials", sdl.trials},
               {"bootstrap", sdl.bootstrap}});
  } else {
    o << "  actuation delay read from the force sensor: not available (" << sdl.why_not << ")\n";
    jd["why_not"] = sdl.why_not;
  }
  const auto tr = tracking_summary(prep);
  const auto& sw = prep.tracking;
  nlohmann::json jt = {{"reference", tr.trials > 0}, {"switched", sw.switched}};
  if (sw.switched) {
    o << "  tracking: on the encoder the admittance reference and the encoder differed by " << g4(sw.rms_um)
      << " um RMS over the windows (x_ref aligned by 1 sample in " << sw.shift1 << " trials, 0 in " << sw.shift0
      << "), and M_adm Δë + D_adm Δė (e = x_ref − x) took " << g4(100 * sw.share) << " % of this disagreement, coefficient "
      << g4(sw.coef) << " (1: the routes differ by the stages' tracking alone), " << g4(100 * sw.heldout_share)
      << " % on held-out trials (lower in " << sw.heldout_better << " of " << sw.trials
      << " left out). Eq. 21 holds for the reference, not the "
      << "encoder: everything in this report is on the reference (as --position-source reference)";
    if (sw.on_encoder.available) o << "; on the encoder the default method gave D " << mat(sw.on_encoder.d) << "  K " << mat(sw.on_encoder.k);
    if (sw.on_tracked.available)
      o << "; with the tracking as a known force on the encoder (estimate_impedance --position-source tracked) D " << mat(sw.on_tracked.d)
        << "  K " << mat(sw.on_tracked.k);
    o << "\n";
    jt.update({{"rms_um", sw.rms_um}, {"share", sw.share}, {"coef", sw.coef}, {"heldout_share", sw.heldout_share},
               {"heldout_better_trials", sw.heldout_better}, {"trials", sw.trials}, {"shift0_trials", sw.shift0},
               {"shift1_trials", sw.shift1}});
    if (sw.on_encoder.available)
      jt["on_encoder"] = {{"D_Nspm", jmat(sw.on_encoder.d)}, {"K_Npm", jmat(sw.on_encoder.k)}};
    if (sw.on_tracked.available)
      jt["on_tracked"] = {{"D_Nspm", jmat(sw.on_tracked.d)}, {"K_Npm", jmat(sw.on_tracked.k)}};
  } else if (tr.trials == 0) {
    o << "  tracking: no admittance reference (x_ref) in the log\n";
  } else {
    o << "  tracking: the admittance reference and the encoder differ by " << g4(tr.rms_um) << " um RMS over the windows (x_ref aligned by 1 sample in "
      << tr.shift1 << " trials, 0 in " << tr.shift0 << ")";
    jt.update({{"rms_um", tr.rms_um}, {"shift0_trials", tr.shift0}, {"shift1_trials", tr.shift1}, {"share", sdl.tracking_share},
               {"coef", sdl.tracking_coef}, {"heldout_share", sdl.tracking_heldout_share}});
    if (sdl.available && sdl.tracking_share > 0.0)
      o << "; M_adm Δë + D_adm Δė (e = x_ref − x) takes " << g4(100 * sdl.tracking_share) << " % of the disagreement, coefficient "
        << g4(sdl.tracking_coef) << ", " << g4(100 * sdl.tracking_heldout_share) << " % held out: "
        << (prep.settings.position == estimation::PositionSource::automatic
                ? "too little, too far from 1 or not held out, for the diagnosis to move to the reference\n"
                : "the diagnosis stays where --position-source put it\n");
    else
      o << ": not part of the disagreement\n";
  }
  o << "\nData: " << prep.n_trials << " trials, " << prep.n_perturbed << " perturbed, " << prep.data.planar.size() << " used";
  if (!prep.excluded.empty()) {
    o << "; excluded:\n";
    for (const auto& e : prep.excluded) o << "  " << e << "\n";
  } else {
    o << "\n";
  }
  r.text = o.str();
  r.json = {{"logs", prep.logs},
            {"trials", prep.n_trials},
            {"perturbed", prep.n_perturbed},
            {"used", prep.data.planar.size()},
            {"excluded", prep.excluded},
            {"t_est_s", prep.t_est_s},
            {"baseline_D_Nspm", jmat(z0.d)},
            {"baseline_K_Npm", jmat(z0.k)},
            {"final_D_Nspm", jmat(z1.d)},
            {"final_K_Npm", jmat(z1.k)},
            {"windows", jw},
            {"sensor_disagreement", {{"rms_share", sd.rms_share}, {"rho", jr}, {"actuation_delay", jd}, {"tracking", jt}}}};
  if (prep.pem.available)
    r.json["default_method"] = {{"method", prep.pem.method},
                                {"D_Nspm", jmat(prep.pem.d)},
                                {"K_Npm", jmat(prep.pem.k)},
                                {"D_ci95_lo", jmat(prep.pem.d_lo)},
                                {"D_ci95_hi", jmat(prep.pem.d_hi)},
                                {"K_ci95_lo", jmat(prep.pem.k_lo)},
                                {"K_ci95_hi", jmat(prep.pem.k_hi)}};
  else
    r.json["default_method"] = {{"error", prep.pem.error}};
  if (dg.misfit_found() && prep.refined.available)
    r.json["default_method_refined"] = {{"alpha", prep.refined.alpha},
                                        {"nll_baseline", prep.refined.nll_baseline},
                                        {"nll_alpha1", prep.refined.nll_alpha1},
                                        {"nll_best", prep.refined.nll_best},
                                        {"D_Nspm", jmat(prep.refined.fit.d)},
                                        {"K_Npm", jmat(prep.refined.fit.k)},
                                        {"D_ci95_lo", jmat(prep.refined.fit.d_lo)},
                                        {"D_ci95_hi", jmat(prep.refined.fit.d_hi)},
                                        {"K_ci95_lo", jmat(prep.refined.fit.k_lo)},
                                        {"K_ci95_hi", jmat(prep.refined.fit.k_hi)}};
  if (dg.misfit_found() && prep.pem_extended.available)
    r.json["default_method_extended"] = {{"method", prep.pem_extended.method},
                                         {"D_Nspm", jmat(prep.pem_extended.d)},
                                         {"K_Npm", jmat(prep.pem_extended.k)},
                                         {"D_ci95_lo", jmat(prep.pem_extended.d_lo)},
                                         {"D_ci95_hi", jmat(prep.pem_extended.d_hi)},
                                         {"K_ci95_lo", jmat(prep.pem_extended.k_lo)},
                                         {"K_ci95_hi", jmat(prep.pem_extended.k_hi)}};
  return r;
}

}  // namespace manip::diagnosis
