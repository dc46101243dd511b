#pragma once
// Statistics shared by the fits: the identifiability flag, the delete-one-
// trial jackknife, Student-t intervals and the regressor's condition number.
#include <vector>

#include <Eigen/Dense>

#include "manip/estimation/estimate.hpp"

namespace manip::estimation {

// Flag rule (docs/estimator.md): an estimate is not identifiable when any
// element's SE exceeds 50 % of max(|element|, 10 % of its matrix's Frobenius
// norm), or the regressor's condition number exceeds 1e8.
void flag_identifiability(ImpedanceEstimate& e, double rel_se_threshold = 0.5);

// Delete-one-trial jackknife standard error from the leave-one-out estimates
// (Efron's (n−1)/n Σ (θ_i − θ̄)²; trials are the independent units).
Eigen::VectorXd jackknife_se(const std::vector<Eigen::VectorXd>& leave_one_out);

// Student-t 0.975 quantile for `dof` degrees of freedom.
double t_quantile_975(int dof);

// Condition number of a regressor / Jacobian after scaling every column to
// unit norm (so the units of M, D and K do not count as ill-conditioning).
double column_normalised_condition(const Eigen::MatrixXd& a);

}  // namespace manip::estimation
