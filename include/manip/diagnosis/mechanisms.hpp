#pragma once
// The mechanism library: each entry is a parametric extension of the
// baseline with a physical meaning, a signature that gives it away, and
// plausible parameter bounds (docs/diagnosis.md lists the sources).
// Parameters come in two kinds: "shape" parameters searched on a grid over
// their physiological range (e.g. reflex delay), and gains, linear in the
// model and solved by least squares for every grid point.
#include <array>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "manip/diagnosis/dataset.hpp"

namespace manip::diagnosis {

struct ParamInfo {
  std::string name, unit;
  double plausible_lo, plausible_hi;  // physiological / physical bounds (report flags values outside)
};

class Mechanism {
 public:
  virtual ~Mechanism() = default;
  [[nodiscard]] virtual std::string id() const = 0;
  [[nodiscard]] virtual std::string title() const = 0;
  [[nodiscard]] virtual std::string signature() const = 0;
  // Empty when applicable, else why not.
  [[nodiscard]] virtual std::string not_applicable(const Dataset&) const { return {}; }
  [[nodiscard]] virtual std::vector<ParamInfo> shape_params() const { return {}; }
  [[nodiscard]] virtual std::vector<ParamInfo> gains() const = 0;
  // Grid of shape settings (one empty setting when there are none).
  [[nodiscard]] virtual std::vector<std::vector<double>> grid(const Dataset&) const { return {{}}; }
  // Smoothed columns for one setting.
  [[nodiscard]] virtual Columns columns(const Dataset&, std::span<const double> setting) const = 0;
  // All settings in an order the mechanism can compute cheaply; f(index into grid(), columns).
  virtual void for_each_setting(const Dataset& d, const std::function<void(std::size_t, const Columns&)>& f) const;
  // True when columns() takes any setting within the grid's range, not only
  // grid points: the engine then continues the search of the reported shape
  // off the grid (engine.cpp, LatticeSearch). Mechanisms whose columns are
  // prepared per grid point (the manipulandum's stage friction) keep false.
  [[nodiscard]] virtual bool searchable_off_grid() const { return false; }
  // columns(d, setting) for many settings off the grid (the engine's search
  // between grid points): what does not depend on the setting is computed
  // once, in the returned function (which keeps a reference to d, and may
  // keep a cache between calls - the reflex keeps its recent low passes -
  // so one function is called from one thread at a time).
  [[nodiscard]] virtual std::function<Columns(std::span<const double>)> columns_of(const Dataset& d) const {
    return [this, &d](std::span<const double> setting) { return columns(d, setting); };
  }
  // Samples of history the columns need at the start of a segment.
  [[nodiscard]] virtual std::size_t history_samples(const Dataset&) const { return 0; }
  // Index into [shape params..., gains...] of the parameter the tests check.
  [[nodiscard]] virtual int main_param() const = 0;

  // How the likelihood check (likelihood_stage.hpp) profiles the mechanism:
  // the shapes it tries itself (empty: the equation-error search's pick) and
  // a fixed direction for a one-gain mechanism (gain per unit of the
  // profiled amplitude; 0: the equation-error gain). A fixed direction and
  // shapes of its own are for mechanisms whose equation-error estimate is
  // noise at realistic magnitudes (the reflex's delay and gain).
  // alpha_min: the profiled amplitude's lower bound (one-sided mechanisms:
  // 0, their opposite direction is a shape of its own). then_first: a second
  // stage, these values of the first shape parameter at the best shape's
  // others (the best of all is refined along it). second_step > 0: then the
  // second shape parameter at the best first, ± this step and the
  // parabola's vertex between them (the directional reflex's direction).
  struct LikelihoodPlan {
    std::vector<std::vector<double>> shapes;
    double gain_per_unit = 0.0;
    double alpha_min = -2.0;
    std::vector<double> then_first{};
    double second_step = 0.0;
  };
  // `setting`: the equation error's best shape (a plan may profile around it).
  [[nodiscard]] virtual LikelihoodPlan likelihood_plan(const Dataset&, std::span<const double> /*setting*/) const { return {}; }
  // A correction of the perturbation force (per planar trial, per sample of
  // the window [onset, onset + T_est]; the input side of eq. 19-21, as
  // extension_correction) simulated from the model at the person's D, K and
  // the given shape and gains: free of the measurement and motor noise that
  // columns built from the isolated signals carry into the input
  // (manipulandum.hpp, simulate_extension). Empty: the mechanism has none
  // (its columns × gains are used).
  [[nodiscard]] virtual std::vector<std::vector<Eigen::Vector2d>> model_correction(const Dataset&, std::span<const double> /*setting*/,
                                                                                 std::span<const double> /*gains*/,
                                                                                 const Eigen::Matrix2d& /*d_nspm*/,
                                                                                 const Eigen::Matrix2d& /*k_npm*/) const {
    return {};
  }
  // The D, K the next pass of the likelihood check simulates model_correction
  // at, given the pass's reference (d0, k0) and the fit it gave (d1, k1,
  // updated in place). Default: the fit itself. A mechanism whose correction
  // copies the person's own D, K (the reflex) makes D, K a fixed point of the
  // fit and steps to it (PlanarReflex).
  virtual void next_reference(const Dataset& /*data*/, std::span<const double> /*setting*/, std::span<const double> /*gains*/,
                              const Eigen::Matrix2d& /*d0*/, const Eigen::Matrix2d& /*k0*/, Eigen::Matrix2d& /*d1*/,
                              Eigen::Matrix2d& /*k1*/) const {}
  // A parameter the report derives from the last gain by a monotone
  // increasing map (the delayed copies' gain g against the intrinsic D, K
  // from their share of the apparent impedance), so its interval is the
  // gain's interval mapped. from_gain null: none.
  struct DerivedGain {
    ParamInfo info{};
    double (*from_gain)(double) = nullptr;
  };
  [[nodiscard]] virtual DerivedGain derived_gain() const { return {}; }
  // A gain that adds to a baseline parameter for some motion (the relaxing
  // stiffness: K + dK is the stiffness to motion faster than tau_relax). The
  // engine reports the sum with its bootstrap interval
  // (Diagnosis::derived_params). Empty base: none.
  struct BaseSum {
    std::string base, gain, name, meaning;
  };
  [[nodiscard]] virtual BaseSum base_sum() const { return {}; }
};

// Stretch reflex (Hammerstein: Kearney, Stein & Parameswaran 1997): half-wave
// rectified velocity, delayed by tau, through a second-order low pass
// (natural frequency fn, damping zeta); one gain per stretch direction.
// Columns: LP[max(v(t - tau), 0)], LP[min(v(t - tau), 0)].
// Position-dependent (quadratic) stiffness: (x - x_ref)^2.
// Stiffness relaxation: x_c - LP_tau[x_c], x_c = x - x_ref (first-order low pass).
// Sensor offset drift: t - t_mid.
// Coulomb-like friction: sign(v).
// Inertia different from the configured one (only when the baseline fixes it): acceleration.

[[nodiscard]] std::vector<std::unique_ptr<Mechanism>> standard_library();

// The reflex's second-order low pass omega^2 / (s^2 + 2 zeta omega s + omega^2),
// bilinear transform prewarped at fn (unit DC gain), as one scipy-layout section.
[[nodiscard]] std::array<double, 6> reflex_lowpass_sos(double fn_hz, double zeta, double dt_s);

}  // namespace manip::diagnosis
