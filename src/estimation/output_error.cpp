#include "manip/estimation/output_error.hpp"

#include <Eigen/Dense>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unsupported/Eigen/MatrixFunctions>

#include "manip/estimation/levenberg_marquardt.hpp"
#include "manip/estimation/uncertainty.hpp"

namespace manip::estimation {
OeWindow make_oe_window(const SessionInfo& info, const TrialData& t, const Mat2& m_bsp, const OeSettings& s) {
  if (t.onset_index < 0) throw std::invalid_argument("trial " + std::to_string(t.trial) + ": no perturbation onset");
  const double fs = info.sample_rate_hz;
  const auto pre = static_cast<std::size_t>(std::llround(s.t_pre_s * fs));
  const auto post = static_cast<std::size_t>(std::llround(s.t_est_s * fs));
  const auto on = static_cast<std::size_t>(t.onset_index);
  if (on < pre) throw std::invalid_argument("trial " + std::to_string(t.trial) + ": onset too close to the trial start");
  if (on + post + 1 > t.size())
    throw std::invalid_argument("trial " + std::to_string(t.trial) + ": ends before the estimation window");
  OeWindow w;
  w.trial = t.trial;
  w.fs_hz = fs;
  w.onset_offset = static_cast<int>(pre);
  w.m_bsp_kg = m_bsp;
  w.m_total_kg = m_bsp + info.m_adm_shoulder_kg() + info.m_handle_shoulder_kg();
  w.d_adm_nspm = info.d_adm_shoulder_nspm();
  w.x_m.assign(t.x_m.begin() + static_cast<std::ptrdiff_t>(on - pre),
               t.x_m.begin() + static_cast<std::ptrdiff_t>(on + post + 1));
  w.u_n.assign(t.u_pert_n.begin() + static_cast<std::ptrdiff_t>(on - pre),
               t.u_pert_n.begin() + static_cast<std::ptrdiff_t>(on + post + 1));
  return w;
}

VariationalZoh discretise_variational(const OeWindow& w, const Mat2& d, const Mat2& k) {
  // Exact zero-order-hold discretisation of the coupled arm + admittance.
  const Mat2 minv = w.m_total_kg.inverse();
  Eigen::Matrix<double, 6, 6> aug = Eigen::Matrix<double, 6, 6>::Zero();
  aug.block<2, 2>(0, 2) = Mat2::Identity();
  aug.block<2, 2>(2, 0) = -minv * k;
  aug.block<2, 2>(2, 2) = -minv * (d + w.d_adm_nspm);
  aug.block<2, 2>(2, 4) = minv;
  const Eigen::Matrix<double, 6, 6> e = (aug / w.fs_hz).exp();
  return {e.block<4, 4>(0, 0), e.block<4, 2>(0, 4)};
}

std::vector<Vec2> simulate_variational(const OeWindow& w, const Mat2& d, const Mat2& k) {
  const auto [phi, gam] = discretise_variational(w, d, k);
  std::vector<Vec2> out(w.x_m.size(), Vec2::Zero());
  Eigen::Vector4d z = Eigen::Vector4d::Zero();
  for (std::size_t i = static_cast<std::size_t>(w.onset_offset); i + 1 < out.size(); ++i) {
    z = phi * z + gam * w.u_n[i];
    out[i + 1] = z.head<2>();
  }
  return out;
}

namespace {

struct OeProblem {
  std::span<const OeWindow> windows;
  std::vector<double> ar;              // whitening filter 1 + a1 q^-1 + ... (empty: none)
  std::vector<Eigen::MatrixXd> basis;  // orthonormal polynomial basis per window
  std::vector<Eigen::VectorXd> y_perp; // projected measurement per window, both axes stacked
  Eigen::Index rows{0};

  OeProblem(std::span<const OeWindow> ws, int order) : windows(ws) {
    for (const auto& w : ws) {
      const auto n = static_cast<Eigen::Index>(w.x_m.size());
      Eigen::MatrixXd p(n, order + 1);
      for (Eigen::Index i = 0; i < n; ++i) {
        const double t = 2.0 * static_cast<double>(i) / static_cast<double>(n - 1) - 1.0;  // [-1, 1]
        double v = 1.0;
        for (int c = 0; c <= order; ++c, v *= t) p(i, c) = v;
      }
      Eigen::HouseholderQR<Eigen::MatrixXd> qr(p);
      basis.push_back(qr.householderQ() * Eigen::MatrixXd::Identity(n, order + 1));
      Eigen::VectorXd y(2 * n);
      for (Eigen::Index i = 0; i < n; ++i) {
        y(i) = w.x_m[static_cast<std::size_t>(i)].x();
        y(n + i) = w.x_m[static_cast<std::size_t>(i)].y();
      }
      y_perp.push_back(project(basis.back(), y));
      rows += 2 * n;
    }
  }
  static Eigen::VectorXd project(const Eigen::MatrixXd& q, const Eigen::VectorXd& y) {
    const auto n = q.rows();
    Eigen::VectorXd out(y.size());
    out.head(n) = y.head(n) - q * (q.transpose() * y.head(n));
    out.tail(n) = y.tail(n) - q * (q.transpose() * y.tail(n));
    return out;
  }
  // In place e[k] <- e[k] + sum_j a_j e[k-j], zero initial conditions.
  void whiten(Eigen::Ref<Eigen::VectorXd> e) const {
    const auto p = static_cast<Eigen::Index>(ar.size());
    for (Eigen::Index k = e.size() - 1; k >= 0; --k) {
      double v = e(k);
      for (Eigen::Index j = 1; j <= p && j <= k; ++j) v += ar[static_cast<std::size_t>(j - 1)] * e(k - j);
      e(k) = v;
    }
  }
  static void unpack(const Eigen::VectorXd& th, Mat2& d, Mat2& k) {
    d << th(0), th(1), th(2), th(3);
    k << th(4), th(5), th(5), th(6);
  }
  // Residual of the projected output error, optionally skipping one window.
  Eigen::VectorXd residual(const Eigen::VectorXd& th, int skip) const {
    Mat2 d, k;
    unpack(th, d, k);
    Eigen::VectorXd r(rows);
    Eigen::Index off = 0;
    for (std::size_t wi = 0; wi < windows.size(); ++wi) {
      const auto n = static_cast<Eigen::Index>(windows[wi].x_m.size());
      if (static_cast<int>(wi) == skip) {
        r.segment(off, 2 * n).setZero();
        off += 2 * n;
        continue;
      }
      const auto sim = simulate_variational(windows[wi], d, k);
      Eigen::VectorXd s(2 * n);
      for (Eigen::Index i = 0; i < n; ++i) {
        s(i) = sim[static_cast<std::size_t>(i)].x();
        s(n + i) = sim[static_cast<std::size_t>(i)].y();
      }
      r.segment(off, 2 * n) = y_perp[wi] - project(basis[wi], s);
      if (!ar.empty()) whiten(r.segment(off, n)), whiten(r.segment(off + n, n));
      off += 2 * n;
    }
    return r;
  }
};

}  // namespace

ImpedanceEstimate fit_output_error(std::span<const OeWindow> windows, const OeSettings& s) {
  if (windows.empty()) throw std::invalid_argument("output-error fit: no perturbed trials");
  OeProblem prob(windows, s.poly_order);
  Eigen::VectorXd th0(7);
  th0 << 10.0, 0.0, 0.0, 10.0, 200.0, 0.0, 200.0;  // a generic arm; LM moves far from it
  LmOptions lo;
  lo.max_iterations = s.max_iterations;
  const auto fit_skipping = [&](const Eigen::VectorXd& start, int skip) {
    return levenberg_marquardt([&](const Eigen::VectorXd& th) { return prob.residual(th, skip); }, start, lo);
  };
  auto fit = fit_skipping(th0, -1);
  if (s.prewhiten_order > 0) {
    // Yule-Walker on the first fit's residuals, pooled over windows and axes.
    const int p = s.prewhiten_order;
    std::vector<double> acf(static_cast<std::size_t>(p + 1), 0.0);
    Eigen::Index off = 0;
    for (const auto& w : windows) {
      const auto n = static_cast<Eigen::Index>(w.x_m.size());
      for (int axis = 0; axis < 2; ++axis) {
        const auto seg = fit.res.segment(off + axis * n, n);
        for (int lag = 0; lag <= p; ++lag)
          for (Eigen::Index k = lag; k < n; ++k) acf[static_cast<std::size_t>(lag)] += seg(k) * seg(k - lag);
      }
      off += 2 * n;
    }
    Eigen::MatrixXd r(p, p);
    Eigen::VectorXd rhs(p);
    for (int i = 0; i < p; ++i) {
      rhs(i) = -acf[static_cast<std::size_t>(i + 1)];
      for (int j = 0; j < p; ++j) r(i, j) = acf[static_cast<std::size_t>(std::abs(i - j))];
    }
    const Eigen::VectorXd a = r.ldlt().solve(rhs);
    if (a.allFinite()) {
      prob.ar.assign(a.data(), a.data() + a.size());
      fit = fit_skipping(fit.theta, -1);
    }
  }
  ImpedanceEstimate e;
  Mat2 d, k;
  OeProblem::unpack(fit.theta, d, k);
  e.d_nspm = d;
  e.k_npm = k;
  Mat2 mean = Mat2::Zero();
  for (const auto& w : windows) mean += w.m_bsp_kg;
  e.m_kg = mean / static_cast<double>(windows.size());
  e.iterations = fit.iterations;
  const auto npoly = static_cast<Eigen::Index>(2 * (s.poly_order + 1) * static_cast<int>(windows.size()));
  const double dof = static_cast<double>(prob.rows - 7 - npoly);
  const double sigma2 = fit.res.squaredNorm() / std::max(1.0, dof);
  Eigen::VectorXd se(7);
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(fit.jac, Eigen::ComputeThinV);
  {
    Eigen::VectorXd inv = svd.singularValues().array().square().inverse().matrix();
    se = ((svd.matrixV() * inv.asDiagonal() * svd.matrixV().transpose()) * sigma2).diagonal().cwiseSqrt();
  }
  e.se_kind = "least-squares (Gauss-Newton)";
  e.ci_factor = 1.96;
  const int n = static_cast<int>(windows.size());
  if (s.jackknife && n >= 3) {
    // Delete-one-trial jackknife: residuals within a trial are strongly
    // correlated (unmodelled movement, motor noise), so the least-squares SE
    // understates the error; trials are the independent units.
    std::vector<Eigen::VectorXd> loo;
    for (int i = 0; i < n; ++i) loo.push_back(fit_skipping(fit.theta, i).theta);
    se = jackknife_se(loo);
    e.se_kind = "jackknife over trials";
    e.ci_factor = t_quantile_975(n - 1);
  }
  e.d_se << se(0), se(1), se(2), se(3);
  e.k_se << se(4), se(5), se(5), se(6);
  e.residual_rms = std::sqrt(fit.res.squaredNorm() / static_cast<double>(prob.rows));
  double var_y = 0.0;
  for (const auto& y : prob.y_perp) var_y += y.squaredNorm();
  if (!prob.ar.empty()) var_y = prob.residual(Eigen::VectorXd::Zero(7), -1).squaredNorm();  // whitened scale
  e.vaf = var_y > 0 ? 1.0 - fit.res.squaredNorm() / var_y : 0.0;
  e.condition = column_normalised_condition(fit.jac);
  e.n_samples = static_cast<int>(prob.rows / 2);
  e.n_params = 7;
  e.n_trials = n;
  flag_identifiability(e);
  if (!fit.converged) {
    e.identifiable = false;
    if (e.flag.empty()) e.flag = "output-error fit did not converge in " + std::to_string(fit.iterations) + " iterations";
  }
  return e;
}

}  // namespace manip::estimation
