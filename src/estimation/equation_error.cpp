#include "manip/estimation/equation_error.hpp"

#include <Eigen/Dense>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "manip/estimation/uncertainty.hpp"

namespace manip::estimation {
namespace {

// A parameter of the identification model: element (i, j) of M (0), D (1)
// or K (2); `sym` marks K12 = K21 shared (eq. 30).
struct Param {
  int mat, i, j;
  bool sym;
};

std::vector<Param> layout(const LsOptions& o) {
  std::vector<Param> p;
  if (o.estimate_m)
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) p.push_back({0, i, j, false});
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) p.push_back({1, i, j, false});
  if (o.k_model == StiffnessModel::symmetric) {
    p.push_back({2, 0, 0, false});
    p.push_back({2, 0, 1, true});
    p.push_back({2, 1, 1, false});
  } else {
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) p.push_back({2, i, j, false});
  }
  return p;
}

void assign(ImpedanceEstimate& e, const std::vector<Param>& lay, const Eigen::VectorXd& z, const Eigen::VectorXd& se) {
  for (std::size_t p = 0; p < lay.size(); ++p) {
    const auto& q = lay[p];
    Mat2& v = q.mat == 0 ? e.m_kg : (q.mat == 1 ? e.d_nspm : e.k_npm);
    Mat2& s = q.mat == 0 ? e.m_se : (q.mat == 1 ? e.d_se : e.k_se);
    v(q.i, q.j) = z(static_cast<Eigen::Index>(p));
    s(q.i, q.j) = se(static_cast<Eigen::Index>(p));
    if (q.sym) {
      v(q.j, q.i) = v(q.i, q.j);
      s(q.j, q.i) = s(q.i, q.j);
    }
  }
}

}  // namespace

ImpedanceEstimate fit_equation_error(std::span<const VariationalWindow> windows, std::span<const Mat2> m_bsp,
                                     const LsOptions& opt) {
  const auto lay = layout(opt);
  const auto np = static_cast<Eigen::Index>(lay.size());
  Eigen::Index rows = 0;
  for (const auto& w : windows) rows += 2 * static_cast<Eigen::Index>(w.size());
  if (rows <= np) throw std::invalid_argument("equation-error fit: not enough samples");
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(rows, np);
  Eigen::VectorXd b(rows);
  Eigen::Index r = 0;
  for (std::size_t wi = 0; wi < windows.size(); ++wi) {
    const auto& w = windows[wi];
    const auto& du = opt.force == ForceSource::admittance ? w.du_ext_adm : w.du_ext_force;
    for (std::size_t k = 0; k < w.size(); ++k) {
      for (int row = 0; row < 2; ++row, ++r) {
        double bk = du[k](row);
        if (!opt.estimate_m) bk -= (m_bsp[wi] * w.dxdd[k])(row);  // eq. 32
        b(r) = bk;
        for (Eigen::Index p = 0; p < np; ++p) {
          const auto& q = lay[static_cast<std::size_t>(p)];
          const Vec2& sig = q.mat == 0 ? w.dxdd[k] : (q.mat == 1 ? w.dxd[k] : w.dx[k]);  // eq. 28/31
          double v = 0.0;
          if (q.i == row) v += sig(q.j);
          if (q.sym && q.j == row) v += sig(q.i);
          a(r, p) = v;
        }
      }
    }
  }
  // SVD instead of the normal equations of eq. 29: same solution, stable.
  Eigen::BDCSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd z = svd.solve(b);
  const Eigen::VectorXd res = b - a * z;
  const double dof = static_cast<double>(rows - np);
  const double sigma2 = res.squaredNorm() / dof;
  const auto& s = svd.singularValues();
  Eigen::VectorXd inv_s2 = s.array().square().inverse().matrix();
  for (Eigen::Index i = 0; i < inv_s2.size(); ++i)
    if (!std::isfinite(inv_s2(i))) inv_s2(i) = std::numeric_limits<double>::quiet_NaN();
  const Eigen::MatrixXd cov = svd.matrixV() * inv_s2.asDiagonal() * svd.matrixV().transpose() * sigma2;
  ImpedanceEstimate e;
  e.m_estimated = opt.estimate_m;
  if (!opt.estimate_m) {
    Mat2 mean = Mat2::Zero();
    for (const auto& m : m_bsp) mean += m;
    e.m_kg = mean / static_cast<double>(std::max<std::size_t>(1, m_bsp.size()));
  }
  assign(e, lay, z, cov.diagonal().cwiseSqrt());
  e.se_kind = "least-squares";
  e.ci_factor = t_quantile_975(static_cast<int>(dof));
  e.residual_rms = std::sqrt(res.squaredNorm() / static_cast<double>(rows));
  const double var_b = (b.array() - b.mean()).square().mean();
  e.vaf = var_b > 0 ? 1.0 - (res.array() - res.mean()).square().mean() / var_b : 0.0;
  e.condition = column_normalised_condition(a);
  e.n_samples = static_cast<int>(rows / 2);
  e.n_params = static_cast<int>(np);
  e.n_trials = static_cast<int>(windows.size());
  flag_identifiability(e);
  return e;
}

}  // namespace manip::estimation
