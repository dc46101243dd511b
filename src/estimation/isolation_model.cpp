// Model-based isolation of the variational dynamics (isolation_model.hpp).
#include "manip/estimation/isolation_model.hpp"

#include <Eigen/Dense>
#include <cmath>
#include <stdexcept>
#include <unsupported/Eigen/MatrixFunctions>

#include "manip/logging/session_stream.hpp"
#include "manip/model/arm.hpp"

namespace manip::estimation {
namespace {

using Vec7 = Eigen::Matrix<double, 7, 1>;

Vec7 pack(const Mat2& d, const Mat2& k) {
  Vec7 t;
  t << d(0, 0), d(0, 1), d(1, 0), d(1, 1), k(0, 0), 0.5 * (k(0, 1) + k(1, 0)), k(1, 1);
  return t;
}

void unpack(const Vec7& t, Mat2& d, Mat2& k) {
  d << t(0), t(1), t(2), t(3);
  k << t(4), t(5), t(5), t(6);
}

// Orthonormal basis of the polynomials of `order` on the window's samples.
Eigen::MatrixXd poly_basis(Eigen::Index n, int order) {
  Eigen::MatrixXd p(n, order + 1);
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t = 2.0 * static_cast<double>(i) / static_cast<double>(n - 1) - 1.0;
    double v = 1.0;
    for (int c = 0; c <= order; ++c, v *= t) p(i, c) = v;
  }
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(p);
  return qr.householderQ() * Eigen::MatrixXd::Identity(n, order + 1);
}

// Residual of one window with the polynomial projected out, both axes stacked.
Eigen::VectorXd residual(const OeWindow& w, const Eigen::MatrixXd& q, const Vec7& th) {
  Mat2 d, k;
  unpack(th, d, k);
  const auto s = simulate_variational(w, d, k);
  const auto n = static_cast<Eigen::Index>(w.x_m.size());
  Eigen::VectorXd r(2 * n);
  for (Eigen::Index i = 0; i < n; ++i) {
    r(i) = w.x_m[static_cast<std::size_t>(i)].x() - s[static_cast<std::size_t>(i)].x();
    r(n + i) = w.x_m[static_cast<std::size_t>(i)].y() - s[static_cast<std::size_t>(i)].y();
  }
  r.head(n) -= q * (q.transpose() * r.head(n));
  r.tail(n) -= q * (q.transpose() * r.tail(n));
  return r;
}

// A few ridge-regularised Gauss-Newton steps of the per-trial output error.
Vec7 refine(const OeWindow& w, const Eigen::MatrixXd& q, const Vec7& th0, const ModelIsolationSettings& s) {
  Vec7 th = th0;
  Eigen::VectorXd r = residual(w, q, th);
  Vec7 prior_w = Vec7::Zero();
  const auto total = [&](const Eigen::VectorXd& res, const Vec7& t) {
    return res.squaredNorm() + (t - th0).cwiseProduct(prior_w).dot(t - th0);
  };
  for (int it = 0; it < s.refine_iterations; ++it) {
    Eigen::MatrixXd jac(r.size(), 7);  // d r / d th, forward differences (the model is smooth in th)
    for (int p = 0; p < 7; ++p) {
      Vec7 tp = th;
      const double h = 1e-6 * std::max(1.0, std::abs(th(p)));
      tp(p) += h;
      jac.col(p) = (residual(w, q, tp) - r) / h;
    }
    const Eigen::Matrix<double, 7, 7> jtj = jac.transpose() * jac;
    if (it == 0) prior_w = s.refine_ridge * jtj.diagonal();
    // min |r + J s|^2 + (th + s - th0)^T W (th + s - th0):  (J^T J + W) s = -(J^T r + W (th - th0))
    Eigen::Matrix<double, 7, 7> a = jtj;
    a.diagonal() += prior_w;
    const Vec7 step = a.ldlt().solve(-(jac.transpose() * r + prior_w.cwiseProduct(th - th0)));
    const Vec7 tn = th + step;
    const Eigen::VectorXd rn = residual(w, q, tn);
    if (!std::isfinite(rn.squaredNorm()) || total(rn, tn) >= total(r, th)) break;
    th = tn;
    r = rn;
  }
  return th;
}

}  // namespace

ModelResponse simulate_variational_states(const OeWindow& w, const Mat2& d, const Mat2& k) {
  const Mat2 minv = w.m_total_kg.inverse();
  const auto [phi, gam] = discretise_variational(w, d, k);
  ModelResponse r;
  const std::size_t n = w.x_m.size();
  r.x.assign(n, Vec2::Zero());
  r.xd.assign(n, Vec2::Zero());
  r.xdd.assign(n, Vec2::Zero());
  Eigen::Vector4d z = Eigen::Vector4d::Zero();
  const auto on = static_cast<std::size_t>(w.onset_offset);
  for (std::size_t i = on; i < n; ++i) {
    r.x[i] = z.head<2>();
    r.xd[i] = z.tail<2>();
    const Eigen::Vector4d zn = phi * z + gam * w.u_n[i];
    // Acceleration of cycle i: the velocity change over the cycle per second, as the
    // admittance's reference acceleration is (v_{i+1} = v_i + dt xdd_i); the last
    // sample, which has no successor, takes the instantaneous value.
    r.xdd[i] = i + 1 < n ? Vec2((zn.tail<2>() - z.tail<2>()) * w.fs_hz)
                         : Vec2(minv * (w.u_n[i] - (d + w.d_adm_nspm) * r.xd[i] - k * r.x[i]));
    z = zn;
  }
  return r;
}

ModelIsolation isolate_model_based(const SessionInfo& info, const std::vector<TrialData>& trials,
                                   const ModelIsolationSettings& s) {
  ModelIsolation out;
  const TwoLinkArm arm(info.anthropometrics);
  std::vector<OeWindow> ow, pw;  // response windows; pem fit windows (longer pre-onset)
  std::vector<VariationalWindow> vw;
  for (const auto& t : trials) {
    if (!t.perturbed || t.onset_index < 0) continue;
    try {
      const Vec2 x_on = t.x_m.at(static_cast<std::size_t>(t.onset_index));
      const auto m_bsp = arm.endpoint_inertia_at(x_on);
      if (!m_bsp) throw std::invalid_argument("trial " + std::to_string(t.trial) + ": onset out of the arm's reach");
      PipelineSettings pipe = s.pipeline;
      pipe.t_est_s = s.oe.t_est_s;
      auto v = isolate_variational(info, t, pipe);  // layout, u_pert and (simulated logs) the twin truth
      auto o = make_oe_window(info, t, *m_bsp, s.oe);
      auto p = s.session_fit == ModelIsolationSettings::SessionFit::pem ? make_pem_window(info, t, *m_bsp, s.pem)
                                                                         : OeWindow{};
      vw.push_back(std::move(v));
      ow.push_back(std::move(o));
      pw.push_back(std::move(p));
    } catch (const std::exception& e) {
      out.issues.push_back({t.trial, e.what()});
    }
  }
  if (ow.empty()) throw std::invalid_argument("model-based isolation: no usable perturbed trial");
  OeSettings o = s.oe;
  o.jackknife = false;
  PemSettings ps = s.pem;
  ps.se = PemSe::fisher;  // SEs are not used here; the Fisher ones come for free
  const bool use_pem = s.session_fit == ModelIsolationSettings::SessionFit::pem;
  const auto session_fit = [&](const std::vector<OeWindow>& fit_o, const std::vector<OeWindow>& fit_p) {
    return use_pem ? fit_prediction_error(fit_p, ps) : fit_output_error(fit_o, o);
  };
  const auto fit = session_fit(ow, pw);
  out.d_session_nspm = fit.d_nspm;
  out.k_session_npm = fit.k_npm;
  const Vec7 th0 = pack(fit.d_nspm, fit.k_npm);
  const Mat2 m_dev = info.m_adm_shoulder_kg() + info.m_handle_shoulder_kg();
  const Mat2 d_adm = info.d_adm_shoulder_nspm();
  for (std::size_t i = 0; i < ow.size(); ++i) {
    const auto& w = ow[i];
    Vec7 th = th0;
    if (s.leave_one_out && ow.size() >= 2) {
      std::vector<OeWindow> rest, rest_p;
      for (std::size_t j = 0; j < ow.size(); ++j)
        if (j != i) rest.push_back(ow[j]), rest_p.push_back(pw[j]);
      const auto f = session_fit(rest, rest_p);
      th = pack(f.d_nspm, f.k_npm);
    }
    const Vec7 th_prior = th;
    if (s.refine_per_trial)
      th = refine(w, poly_basis(static_cast<Eigen::Index>(w.x_m.size()), s.oe.poly_order), th_prior, s);
    Mat2 d, k;
    unpack(th, d, k);
    const auto resp = simulate_variational_states(w, d, k);
    auto& v = vw[i];
    const auto on = static_cast<std::size_t>(w.onset_offset);
    for (std::size_t j = 0; j < v.size(); ++j) {
      v.dx[j] = resp.x[on + j];
      v.dxd[j] = resp.xd[on + j];
      v.dxdd[j] = resp.xdd[on + j];
      v.du_ext_adm[j] = v.u_pert[j] - m_dev * v.dxdd[j] - d_adm * v.dxd[j];  // eq. 21
    }
    out.d_trial_nspm.push_back(d);
    out.k_trial_npm.push_back(k);
  }
  out.windows = std::move(vw);
  return out;
}

ModelIsolation isolate_model_based_log(const std::string& path, const ModelIsolationSettings& s) {
  std::vector<TrialData> trials;
  SessionInfo info;
  TrialAssembler asmb([&](const SessionInfo& i, TrialData&& t) {
    info = i;
    if (t.perturbed && t.onset_index >= 0) trials.push_back(std::move(t));
  });
  logging::read_log(path, asmb);
  asmb.finish();
  if (!asmb.has_session()) throw std::runtime_error(path + ": no session message (MANIP_SESSION) in the log");
  auto r = isolate_model_based(info, trials, s);
  for (const auto& is : asmb.issues()) r.issues.push_back(is);
  return r;
}

}  // namespace manip::estimation
