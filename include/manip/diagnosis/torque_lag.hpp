#pragma once
// Torque-channel lag of a single-joint record, fitted by output error
// (docs/diagnosis.md, "Torque-channel lag").
//
// The recorded torque is the joint's through a first-order lag T (a torque
// amplifier's or anti-aliasing filter, a skew of the acquisition channels):
// tau_m = LP_T[tau], LP_T = 1 / (1 + T s). The model is linear in its gains
// for a fixed T when every column (I, B, K, the accepted mechanisms') goes
// through LP_T, so T is profiled on a grid and the gains solved by least
// squares at each point. Unlike an equation-error column -T dtau_m/dt (built
// from the noisy output itself, attenuated towards 0), the lagged columns
// come from the position only. The first-order expansion
// tau / (1 + T s) = K x + (B - T K) s x + (I - T B + T^2 K) s^2 x + O(s^3)
// shows what identifies T: the O(s^3) part of the response, which the
// baseline's I, B cannot take up.
//
// Not a library mechanism: it changes every column, where the engine's
// mechanisms add columns to the baseline. It runs after the diagnosis, on
// its model (baseline + named mechanisms at their shapes), with the engine's
// blocks and folds: each fold's T is chosen on the other folds, the fold
// gain is the relative reduction of the held-out squared error against
// T = 0, tested one-sided over the folds at EngineOptions::alpha divided by
// the number of tests (round 1's applicable candidates and this one).
// A lag of the position channel instead is not searched: on the measured
// ankle records a "position lag" takes up the unnamed fast component of
// z_df3 (docs/diagnosis.md), and encoders have no filter lag.
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "manip/diagnosis/engine.hpp"

namespace manip::diagnosis {

struct TorqueLagFit {
  bool done = false;
  std::string why_not;  // when !done
  std::vector<double> grid_s;   // the lags tried: 0 to 60 ms in 0.5 ms steps
  std::vector<double> sse;      // full-data squared error per grid point
  std::vector<double> fold_gain;  // per fold, at the T its training folds chose
  stats::OneSidedT test;
  double alpha = 0.0;        // the test's level: EngineOptions::alpha / (1 + round 1's applicable candidates)
  bool significant = false;  // test.p_value < alpha, mean > 0, T inside the grid
  bool at_edge = false;      // the full-data optimum on the 60 ms end of the grid
  Interval lag_s;            // full-data optimum (parabola through the grid's 3 best), block-bootstrap percentile interval
  std::vector<ParamEstimate> params;  // the model's gains at the lag (I, B, K, c, the named mechanisms'), bootstrap intervals
  std::vector<ParamEstimate> params_no_lag;  // the same model at T = 0 (full-data values)
};

[[nodiscard]] TorqueLagFit fit_torque_lag(const Dataset& d, const Diagnosis& res, const std::vector<std::unique_ptr<Mechanism>>& lib,
                                          const EngineOptions& opt);

// The report's section (text, ends with a newline) and its JSON.
[[nodiscard]] std::string torque_lag_text(const TorqueLagFit& f);
[[nodiscard]] nlohmann::json torque_lag_json(const TorqueLagFit& f);

}  // namespace manip::diagnosis
