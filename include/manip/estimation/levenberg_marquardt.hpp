#pragma once
// Levenberg-Marquardt on a residual function with a forward-difference
// Jacobian. Used by the output-error fit (output_error.cpp); the prediction-
// error fit (pem.cpp) maximises its likelihood by Fisher scoring instead.
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <functional>

namespace manip::estimation {

struct LmOptions {
  int max_iterations{60};
  double rel_cost_tol{1e-12};
  double step_tol{1e-10};
  // Optional projection applied to every trial point (bounds on parameters).
  std::function<void(Eigen::VectorXd&)> project{};
  // Relative finite-difference step per parameter (default 1e-6 * max(1, |θ|)).
  std::function<double(Eigen::Index, double)> fd_step{};
};

struct LmResult {
  Eigen::VectorXd theta;
  Eigen::MatrixXd jac;  // at the last accepted point's linearisation
  Eigen::VectorXd res;
  int iterations{0};
  bool converged{false};
};

// `residual(θ)` returns the residual vector (fixed length for all θ).
template <class ResidualFn>
LmResult levenberg_marquardt(const ResidualFn& residual, Eigen::VectorXd th, const LmOptions& o = {}) {
  LmResult out;
  if (o.project) o.project(th);
  Eigen::VectorXd r = residual(th);
  double cost = r.squaredNorm();
  double lambda = 1e-3;
  const auto np = th.size();
  Eigen::MatrixXd jac(r.size(), np);
  for (int it = 0; it < o.max_iterations; ++it) {
    out.iterations = it + 1;
    for (Eigen::Index p = 0; p < np; ++p) {  // forward differences; the models are smooth in θ
      Eigen::VectorXd tp = th;
      const double h = o.fd_step ? o.fd_step(p, th(p)) : 1e-6 * std::max(1.0, std::abs(th(p)));
      tp(p) += h;
      jac.col(p) = (residual(tp) - r) / h;
    }
    const Eigen::MatrixXd jtj = jac.transpose() * jac;
    const Eigen::VectorXd g = jac.transpose() * r;
    bool improved = false;
    for (int tries = 0; tries < 12; ++tries) {
      Eigen::MatrixXd aug = jtj;
      aug.diagonal() += lambda * jtj.diagonal().cwiseMax(1e-30);
      Eigen::VectorXd tn = th - aug.ldlt().solve(g);
      if (o.project) o.project(tn);
      const Eigen::VectorXd rn = residual(tn);
      const double cn = rn.squaredNorm();
      if (std::isfinite(cn) && cn < cost) {
        const double rel = (cost - cn) / std::max(cost, 1e-300);
        const double step = (tn - th).norm();
        th = tn;
        r = rn;
        cost = cn;
        lambda = std::max(lambda / 10.0, 1e-12);
        improved = true;
        if (rel < o.rel_cost_tol || step < o.step_tol * (1.0 + th.norm())) out.converged = true;
        break;
      }
      lambda *= 10.0;
    }
    if (!improved) {
      out.converged = true;  // no descent direction left: at a minimum
      break;
    }
    if (out.converged) break;
  }
  out.theta = th;
  out.res = r;
  out.jac = jac;
  return out;
}

}  // namespace manip::estimation
