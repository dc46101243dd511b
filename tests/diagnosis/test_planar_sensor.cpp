// Force-sensor mechanisms of the manipulandum library (src/diagnosis/planar_sensor.cpp;
// docs/diagnosis.md, "Force-sensor mechanisms"): the force-sensor lag's column
// against hand-computed values, and hidden sensor_lag sessions diagnosed the
// way test_manipulandum.cpp diagnoses the other hidden mechanisms (its
// run_case: same design, noise, engine options and refit).
#include <catch2/catch.hpp>

#include <cmath>
#include <map>
#include <sstream>

#include "manip/diagnosis/manipulandum.hpp"
#include "manip/estimation/variational.hpp"
#include "manip/sim/hidden_effects.hpp"
#include "manip/sim/presets.hpp"

using namespace manip;
using namespace manip::diagnosis;
using Eigen::Matrix2d;
using Eigen::Vector2d;

namespace {

struct Outcome {
  Diagnosis dg;
  PemBaseline pem, pem_ext;
  double alpha = 1.0;
  Matrix2d d_app{Matrix2d::Zero()}, k_app{Matrix2d::Zero()};
};

// test_manipulandum.cpp's run_case (100 movements, 3 reps, realistic noise,
// bootstrap 50, plausible parameters only, ranked by t; pem refit with the
// extension's amplitude refined by the likelihood).
Outcome run_case(const std::vector<sim::HiddenEffect>& effects, std::uint64_t hidden_seed) {
  sim::SessionDesign base;
  base.n_movements = 100;
  base.reps_per_angle = 3;
  base.session.source = "manip_sim/linear";
  auto person = sim::table1_person();
  sim::apply_noise(sim::NoiseLevel::realistic, base, person);
  auto hs = sim::make_hidden_session(base, person, effects, hidden_seed);
  std::vector<CollectedSession> ses(1);
  ses[0].name = "hidden";
  LogCollector col(ses[0]);
  const auto sum = sim::run_session(hs.design, *hs.person, col);
  col.finish();
  Outcome o;
  if (sum.apparent) {
    o.d_app = sum.apparent->d_nspm;
    o.k_app = sum.apparent->k_npm;
  }
  PlanarOptions po;
  EngineOptions eo;
  eo.bootstrap = 50;
  eo.require_plausible = true;
  eo.rank_by_t = true;
  auto prep = prepare_planar(ses, po, eo.folds);
  const auto lib = planar_library(po.nuisance_order);
  o.dg = diagnose(prep.data, lib, eo);
  o.pem = prep.pem;
  o.pem_ext = prep.pem;
  if (o.dg.misfit_found()) {
    const auto rf = refine_with_default_method(prep, o.dg, lib);
    o.pem_ext = rf.fit;
    o.alpha = rf.alpha;
  }
  return o;
}

double frob(const Matrix2d& e, const Matrix2d& t) { return (e - t).norm() / t.norm(); }

std::string show(const Matrix2d& m) {
  std::ostringstream o;
  o.precision(4);
  o << "[" << m(0, 0) << " " << m(0, 1) << "; " << m(1, 0) << " " << m(1, 1) << "]";
  return o.str();
}

}  // namespace

TEST_CASE("planar sensor: force_sensor_lag is in the library, bounds 0-10 ms") {
  const auto lib = planar_library();
  const Mechanism* m = nullptr;
  for (const auto& x : lib)
    if (x->id() == "force_sensor_lag") m = x.get();
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

namespace {
// The checks on a hidden sensor_lag session (as test_manipulandum.cpp's
// check_named): named first, tau (refined by the likelihood) within 20 %, the
// held-out gain and its lower bound > 0, the pem refit's K within 10 % of the
// apparent truth (relative Frobenius error).
void check_lag_named(double tau, std::uint64_t seed) {
  const auto o = run_case({sim::parse_hidden_effect("sensor_lag:" + std::to_string(tau))}, seed);
  INFO("hidden sensor_lag " << tau << " s, seed " << seed << "; accepted: " << (o.dg.accepted.empty() ? "none" : o.dg.accepted.front()));
  INFO("pem K " << show(o.pem.k) << " D " << show(o.pem.d) << "; refit K " << show(o.pem_ext.k) << " D " << show(o.pem_ext.d)
                << "; apparent K " << show(o.k_app) << " D " << show(o.d_app));
  REQUIRE(o.dg.misfit_found());
  CHECK(o.dg.accepted.front() == "force_sensor_lag");
  const auto* p = o.dg.find_final("sensor_lag");
  REQUIRE(p);
  INFO("tau = " << o.alpha * p->est.value << " (equation error " << p->est.value << ", alpha " << o.alpha << ")");
  CHECK(std::fabs(o.alpha * p->est.value - tau) < 0.20 * tau);
  CHECK(o.dg.heldout_gain.value > 0.0);
  CHECK(o.dg.heldout_gain.lo > 0.0);
  CHECK(frob(o.pem_ext.k, o.k_app) < 0.10);
}
}  // namespace

TEST_CASE("planar sensor: hidden force-sensor lag 3 ms (middle) is named with tau within 20 % and K after within 10 %", "[.known-miss]") {
  check_lag_named(0.003, 1);
}

TEST_CASE("planar sensor: hidden force-sensor lag 6 ms (large) is named with tau within 20 % and K after within 10 %", "[.known-miss]") {
  check_lag_named(0.006, 1);
}

TEST_CASE("planar sensor: hidden force-sensor offset 5 N names nothing and pem K is within 10 % of the apparent truth", "[.known-miss]") {
  const auto o = run_case({sim::parse_hidden_effect("sensor_offset:5")}, 1);
  INFO("accepted: " << (o.dg.accepted.empty() ? "none" : o.dg.accepted.front()) << "; pem K " << show(o.pem.k)
                    << " apparent K " << show(o.k_app));
  CHECK_FALSE(o.dg.misfit_found());
  CHECK(frob(o.pem.k, o.k_app) < 0.10);
}

// Below the detection limit (docs/diagnosis.md, "Force-sensor mechanisms"):
// a realistic 1.5 ms lag is not named (nor anything else in its place), and
// what it does to the default estimate is D, not K: pem K stays within 10 %
// of the apparent truth while D is > 20 % off (measured on seed 1: K 7.7 %,
// D11 15.7 for 10.5 N s/m). The clean and 2 ms actuation-delay cases of
// test_manipulandum.cpp run with the library that holds the lag.
TEST_CASE("planar sensor: hidden force-sensor lag 1.5 ms is not named, pem K within 10 % and D more than 20 % off") {
  const auto o = run_case({sim::parse_hidden_effect("sensor_lag:0.0015")}, 1);
  INFO("accepted: " << (o.dg.accepted.empty() ? "none" : o.dg.accepted.front()) << "; pem K " << show(o.pem.k) << " D "
                    << show(o.pem.d) << "; apparent K " << show(o.k_app) << " D " << show(o.d_app));
  CHECK_FALSE(o.dg.misfit_found());
  CHECK(frob(o.pem.k, o.k_app) < 0.10);
  CHECK(frob(o.pem.d, o.d_app) > 0.20);
}
