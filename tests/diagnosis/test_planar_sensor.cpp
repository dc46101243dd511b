// Force-sensor mechanisms of the manipulandum library (src/diagnosis/planar_sensor.cpp;
// docs/diagnosis.md, "Force-sensor mechanisms"): the force-sensor lag's column
// against hand-computed values, and hidden sensor_lag sessions diagnosed the
// way test_manipulandum.cpp diagnoses the other hidden mechanisms (its
// run_case, hidden_case.hpp).
#include <catch2/catch.hpp>

#include <cmath>
#include <map>
#include <sstream>

#include <unsupported/Eigen/MatrixFunctions>

#include "hidden_case.hpp"
#include "manip/diagnosis/manipulandum.hpp"
#include "manip/estimation/variational.hpp"
#include "manip/sim/hidden_effects.hpp"
#include "manip/sim/presets.hpp"

using namespace manip;
using namespace manip::diagnosis;
using namespace manip::diagnosis::testing;
using Eigen::Matrix2d;
using Eigen::Vector2d;

TEST_CASE("planar sensor: force_sensor_lag is in the library, bounds 0-10 ms") {
  const auto lib = planar_library();
  const Mechanism* m = find_mechanism(lib, "force_sensor_lag");
  REQUIRE(m);
  REQUIRE(m->gains().size() == 1);
  CHECK(m->gains()[0].name == "sensor_lag");
  CHECK(m->gains()[0].plausible_lo == 0.0);
  CHECK(m->gains()[0].plausible_hi == 0.010);
  CHECK(m->shape_params().empty());
}

TEST_CASE("planar sensor: the lag column d/dt(u - du_ext_21 - M_handle ddx) - du/dt against hand-computed values") {
  // One trial of 400 samples at 1 kHz; u_pert a ramp r t on axis 0 and 0 on
  // axis 1. Far from the window's ends (more than the SG half-window) the
  // smoothed rate of a ramp is r exactly (the SG filter keeps cubics), so the
  // column is the central difference of q = u − Δu_ext(21) − 0.25 Δẍ minus r.
  Dataset d;
  d.dt_s = 0.001;
  d.smoothing_cutoff_hz = 30.0;
  const std::size_t n = 400;
  const double r = 50.0;  // N/s
  PlanarTrial p;
  for (std::size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * d.dt_s;
    p.u_pert.emplace_back(r * t, 0.0);
    p.du_ext_adm.emplace_back(std::sin(20 * t), 0.3 * t * t);
    p.dxdd.emplace_back(std::cos(7 * t), t);
    p.dx.emplace_back(0, 0);
    p.dxd.emplace_back(0, 0);
    p.u_pert_rate.emplace_back(r, 0.0);
  }
  d.planar.push_back(p);
  for (int a = 0; a < 2; ++a) {
    Segment s;
    s.group = 0;
    s.axis = a;
    s.planar = 0;
    s.y.assign(n, 0.0);
    s.last = n;
    d.segments.push_back(s);
  }
  estimation::PipelineSettings ps;
  const int win = estimation::sg_window_for(ps, 1000.0);
  REQUIRE(static_cast<std::size_t>(win) < n / 2);
  const auto c = make_force_sensor_lag(0.25)->columns(d, {});
  REQUIRE(c.size() == 2);
  const std::size_t k = 200;
  const double t = 0.2, dt = d.dt_s;
  auto q0 = [&](double tt) { return r * tt - std::sin(20 * tt) - 0.25 * std::cos(7 * tt); };
  auto q1 = [&](double tt) { return -0.3 * tt * tt - 0.25 * tt; };
  CHECK(c[0][0][k] == Approx((q0(t + dt) - q0(t - dt)) / (2 * dt) - r).epsilon(1e-6));
  CHECK(c[1][0][k] == Approx((q1(t + dt) - q1(t - dt)) / (2 * dt)).epsilon(1e-6));
  // By hand at t = 0.2 s: q0' = r − 20 cos(4) + 1.75 sin(1.4) -> column ≈ 13.07 + 1.72 = 14.80;
  // q1' = −0.6 t − 0.25 = −0.37.
  CHECK(c[0][0][k] == Approx(-20 * std::cos(4.0) + 1.75 * std::sin(1.4)).epsilon(1e-4));
  CHECK(c[1][0][k] == Approx(-0.37).epsilon(1e-9));
  // One-sided at the window's first sample; M_handle = 0 drops the Δx⃛ term.
  const auto c0 = make_force_sensor_lag(0.0)->columns(d, {});
  CHECK(c0[1][0][0] == Approx((-0.3 * dt * dt) / dt).epsilon(1e-9));
}

TEST_CASE("planar sensor: the lag's model correction against the exact discretisation of the lagged admittance") {
  // Independent reference: the continuous system z = (Δx, Δẋ, Δf_r),
  //   Δẋ' = M_adm⁻¹ (Δf_r + u − D_adm Δẋ),  τ Δḟ_r = Δf_s − Δf_r,
  //   Δf_s = −(M_BSP + M_handle) Δẋ' − D Δẋ − K Δx,
  // discretised exactly for a held u (matrix exponentials), and the
  // correction Δf_s − Δf_r = C z + E u averaged over each hold from
  // ∫₀^h z = Γ₁ z_k + Γ₂ B u_k (Γ₁, Γ₂ from one block exponential).
  using Mat6 = Eigen::Matrix<double, 6, 6>;
  Dataset d = one_pulse_trial();
  const PlanarTrial& p = d.planar.front();
  const std::size_t n = p.u_pert.size();
  Matrix2d dm, km;
  dm << 12.0, -3.0, -3.0, 8.0;
  km << 150.0, -60.0, -60.0, 340.0;
  const double tau = 0.003;
  const auto lag = make_force_sensor_lag();
  const std::vector<double> g{tau};
  const auto c = lag->model_correction(d, {}, g, dm, km);
  REQUIRE(c.size() == 1);
  REQUIRE(c[0].size() == n);

  const Matrix2d mi = p.m_adm.inverse(), mp = p.m_bsp + p.m_handle, I = Matrix2d::Identity();
  Mat6 a = Mat6::Zero();
  Eigen::Matrix<double, 6, 2> b = Eigen::Matrix<double, 6, 2>::Zero();
  a.block<2, 2>(0, 2) = I;
  a.block<2, 2>(2, 2) = -mi * p.d_adm;
  a.block<2, 2>(2, 4) = mi;
  b.block<2, 2>(2, 0) = mi;
  // τ ḟ = −mp v̇ − D v − K x − f
  a.block<2, 2>(4, 0) = -km / tau;
  a.block<2, 2>(4, 2) = (-dm + mp * mi * p.d_adm) / tau;
  a.block<2, 2>(4, 4) = (-mp * mi - I) / tau;
  b.block<2, 2>(4, 0) = -mp * mi / tau;
  Eigen::Matrix<double, 2, 6> cc;
  cc << -km, -dm + mp * mi * p.d_adm, -mp * mi - I;
  const Matrix2d ee = -mp * mi;
  Eigen::Matrix<double, 18, 18> big = Eigen::Matrix<double, 18, 18>::Zero();
  big.block<6, 6>(0, 0) = a;
  big.block<6, 6>(0, 6) = Mat6::Identity();
  big.block<6, 6>(6, 12) = Mat6::Identity();
  const Eigen::Matrix<double, 18, 18> eb = (big * d.dt_s).exp();
  const Mat6 phi = eb.block<6, 6>(0, 0), g1 = eb.block<6, 6>(0, 6), g2 = eb.block<6, 6>(0, 12);
  Eigen::Matrix<double, 6, 1> z = Eigen::Matrix<double, 6, 1>::Zero();
  double worst = 0.0, peak = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    const Vector2d u = p.u_pert[k];
    const Eigen::Matrix<double, 6, 1> zint = g1 * z + g2 * b * u;
    const Vector2d ref = cc * zint / d.dt_s + ee * u;
    worst = std::max(worst, (c[0][k] - ref).norm());
    peak = std::max(peak, ref.norm());
    z = phi * z + g1 * b * u;
  }
  INFO("largest difference " << worst << " N against a peak correction of " << peak << " N");
  CHECK(peak > 0.1);  // the correction is not trivially small here
  CHECK(worst < 1e-6 * peak);
  // A lead continues the lag linearly (refused by the bounds, but the profile may evaluate it).
  const std::vector<double> gn{-tau};
  const auto cn = lag->model_correction(d, {}, gn, dm, km);
  CHECK((cn[0][300] + c[0][300]).norm() == Approx(0.0).margin(1e-12));
  // The mechanisms that are linear in the variational state have one; the
  // actuation delay (exact from u_pert alone) and the friction (absolute
  // stage velocity) have none.
  const std::vector<double> delay{0.03};
  for (const auto& m : planar_library(true, true)) {
    const bool has = !m->model_correction(d, delay, std::vector<double>(m->gains().size(), 0.0), dm, km).empty();
    INFO(m->id());
    const std::string id = m->id();
    CHECK(has == (id == "force_sensor_lag" || id == "handle_mass" || id == "wrong_segment_inertia" || id == "curl_stiffness" ||
                  id == "short_latency_reflex" || id == "early_feedback" || id == "directional_reflex"));
  }
}

TEST_CASE("planar sensor: hidden force-sensor lag 3 ms (middle) is named with tau within 20 % and K after within 10 %") {
  const Case c{{sim::parse_hidden_effect("sensor_lag:0.003")}, 1};
  check_named(c, run_case(c));
}

// Passes (2026-11-26); out of CI for time (the 3 ms case is the middle magnitude).
TEST_CASE("planar sensor: hidden force-sensor lag 6 ms (large) is named with tau within 20 % and K after within 10 %", "[.extra]") {
  const Case c{{sim::parse_hidden_effect("sensor_lag:0.006")}, 1};
  check_named(c, run_case(c));
}

TEST_CASE("planar sensor: hidden force-sensor offset 5 N names nothing and pem K is within 10 % of the apparent truth", "[.known-miss]") {
  const auto o = run_case(Case{{sim::parse_hidden_effect("sensor_offset:5")}, 1});
  INFO("accepted: " << (o.dg.accepted.empty() ? "none" : o.dg.accepted.front()) << "; pem K " << show(o.pem.k)
                    << " apparent K " << show(o.k_app));
  CHECK_FALSE(o.dg.misfit_found());
  CHECK(frob(o.pem.k, o.k_app) < 0.10);
}

// The equation-error search does not see a realistic 1.5 ms lag (its
// column differentiates the isolated positions three times); the likelihood
// check with the lag simulated from the model does (docs/diagnosis.md,
// "Model-based corrections"). What the lag does to the default estimate is
// D, not K: pem K within 10 % of the apparent truth, D more than 20 % off
// (seed 1: K 7.7 %, D11 15.7 for 10.5 N s/m); the corrected D is back within 20 %.
TEST_CASE("planar sensor: hidden force-sensor lag 1.5 ms: missed by the equation error, named by the likelihood, D repaired") {
  const auto o = run_case(Case{{sim::parse_hidden_effect("sensor_lag:0.0015")}, 1});
  INFO("equation error: " << (o.dg.accepted.empty() ? "none" : o.dg.accepted.front()) << "; named: "
                          << (o.concl.named.empty() ? "none" : o.concl.named.front()) << "; pem K " << show(o.pem.k) << " D "
                          << show(o.pem.d) << "; apparent K " << show(o.k_app) << " D " << show(o.d_app));
  CHECK_FALSE(o.dg.misfit_found());
  CHECK(frob(o.pem.k, o.k_app) < 0.10);
  CHECK(frob(o.pem.d, o.d_app) > 0.20);
  REQUIRE_FALSE(o.concl.named.empty());
  CHECK(o.concl.named.front() == "force_sensor_lag");
  REQUIRE(o.concl.has_corrected);
  INFO("corrected D " << show(o.concl.corrected.d));
  CHECK(frob(o.concl.corrected.d, o.d_app) < 0.20);
  CHECK(frob(o.concl.corrected.k, o.k_app) < 0.10);
}
