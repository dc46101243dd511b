#include "manip/sim/truth.hpp"

#include <cmath>

#include <Eigen/QR>

namespace manip::sim {

std::optional<ApparentImpedance> fit_apparent_impedance(std::span<const VariationalSamples> windows) {
  std::size_t n = 0;
  Mat2 m_mean = Mat2::Zero();
  for (const auto& w : windows) {
    const std::size_t nw = w.dx_m.size();
    if (w.dxd_mps.size() != nw || w.dxdd_mps2.size() != nw || w.du_ext_n.size() != nw) return std::nullopt;
    n += nw;
    m_mean += w.m_bsp_kg;
  }
  if (n < 8) return std::nullopt;
  // Columns [Δẋ1 Δẋ2 Δx1 Δx2], scaled to unit RMS so that the rank decision
  // compares like with like (velocities ~1e-2 m/s, positions ~1e-3 m).
  Eigen::MatrixXd a(static_cast<Eigen::Index>(n), 4);
  Eigen::MatrixXd b(static_cast<Eigen::Index>(n), 2);
  Eigen::Index r = 0;
  for (const auto& w : windows)
    for (std::size_t k = 0; k < w.dx_m.size(); ++k, ++r) {
      a(r, 0) = w.dxd_mps[k].x();
      a(r, 1) = w.dxd_mps[k].y();
      a(r, 2) = w.dx_m[k].x();
      a(r, 3) = w.dx_m[k].y();
      b.row(r) = (w.du_ext_n[k] - w.m_bsp_kg * w.dxdd_mps2[k]).transpose();
    }
  Eigen::Vector4d scale;
  for (int j = 0; j < 4; ++j) {
    scale(j) = a.col(j).norm() / std::sqrt(static_cast<double>(n));
    if (!(scale(j) > 0.0) || !std::isfinite(scale(j))) return std::nullopt;
    a.col(j) /= scale(j);
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(a);
  // A single direction leaves the scaled regressors with a condition number
  // ~1e3-1e4 (small bending of the response): treat that as rank-deficient.
  qr.setThreshold(1e-3);
  if (qr.rank() < 4) return std::nullopt;
  const Eigen::MatrixXd theta = qr.solve(b);  // 4 x 2: column i = row i of [D K]
  ApparentImpedance out;
  out.m_bsp_kg = m_mean / static_cast<double>(windows.size());
  out.n_samples = static_cast<int>(n);
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 2; ++j) {
      out.d_nspm(i, j) = theta(j, i) / scale(j);
      out.k_npm(i, j) = theta(2 + j, i) / scale(2 + j);
    }
  const Eigen::MatrixXd res = b - a * theta;
  out.rms_residual_n = std::sqrt(res.squaredNorm() / (2.0 * static_cast<double>(n)));
  out.rms_force_n = std::sqrt(b.squaredNorm() / (2.0 * static_cast<double>(n)));
  return out;
}

}  // namespace manip::sim
