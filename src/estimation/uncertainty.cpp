#include "manip/estimation/uncertainty.hpp"

#include <Eigen/Dense>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace manip::estimation {

double column_normalised_condition(const Eigen::MatrixXd& a) {
  Eigen::MatrixXd an = a;
  for (Eigen::Index c = 0; c < an.cols(); ++c) {
    const double n = an.col(c).norm();
    if (n > 0) an.col(c) /= n;
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(an);
  const auto& s = svd.singularValues();
  return s(s.size() - 1) > 0 ? s(0) / s(s.size() - 1) : std::numeric_limits<double>::infinity();
}

Eigen::VectorXd jackknife_se(const std::vector<Eigen::VectorXd>& loo) {
  const auto n = static_cast<double>(loo.size());
  Eigen::VectorXd mean = Eigen::VectorXd::Zero(loo.front().size());
  for (const auto& t : loo) mean += t;
  mean /= n;
  Eigen::VectorXd var = Eigen::VectorXd::Zero(mean.size());
  for (const auto& t : loo) var += (t - mean).array().square().matrix();
  return (var * ((n - 1.0) / n)).cwiseSqrt();
}

double t_quantile_975(int dof) {
  static const double table[] = {12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
                                 2.201,  2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
                                 2.080,  2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042};
  if (dof < 1) return std::numeric_limits<double>::quiet_NaN();
  if (dof <= 30) return table[dof - 1];
  // Cornish-Fisher expansion about the normal quantile; < 1e-3 off beyond 30 dof.
  const double z = 1.959964, n = dof;
  return z + (z * z * z + z) / (4 * n) + (5 * std::pow(z, 5) + 16 * z * z * z + 3 * z) / (96 * n * n);
}

void flag_identifiability(ImpedanceEstimate& e, double thr) {
  auto check = [&](const Mat2& v, const Mat2& se, const char* name) {
    const double floor = 0.1 * v.norm();
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) {
        if (!std::isfinite(se(i, j))) continue;
        if (se(i, j) > thr * std::max(std::abs(v(i, j)), floor)) {
          e.identifiable = false;
          if (e.flag.empty())
            e.flag = std::string(name) + std::to_string(i + 1) + std::to_string(j + 1) + " SE " +
                     std::to_string(se(i, j)) + " exceeds " + std::to_string(static_cast<int>(thr * 100)) +
                     "% of its scale";
        }
      }
  };
  check(e.d_nspm, e.d_se, "D");
  check(e.k_npm, e.k_se, "K");
  if (e.condition > 1e8) {
    e.identifiable = false;
    if (e.flag.empty()) e.flag = "condition number " + std::to_string(e.condition) + " > 1e8";
  }
}

}  // namespace manip::estimation
