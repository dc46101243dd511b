#pragma once
// The paper's estimator: equation error on isolated variational signals,
// linear least squares (eq. 24-32), per trial or pooled over trials.
#include <span>

#include "manip/estimation/estimate.hpp"
#include "manip/estimation/variational.hpp"

namespace manip::estimation {

// ---- Equation error on isolated variational signals (eq. 24-32) ----------
enum class StiffnessModel { symmetric, full };
enum class ForceSource { admittance, sensor };  // Δu_ext by eq. 21 or from the force sensor

struct LsOptions {
  StiffnessModel k_model{StiffnessModel::symmetric};  // eq. 30 (paper) or 8 parameters
  bool estimate_m{false};                             // eq. 24-29 instead of M_BSP fixed
  ForceSource force{ForceSource::admittance};
};

// Stacks the windows (one: per-trial; many: pooled) and solves by SVD.
// m_bsp[i] is the a priori inertia for window i (eq. 16; ignored if estimate_m).
ImpedanceEstimate fit_equation_error(std::span<const VariationalWindow> windows, std::span<const Mat2> m_bsp,
                                     const LsOptions& opt);

}  // namespace manip::estimation
