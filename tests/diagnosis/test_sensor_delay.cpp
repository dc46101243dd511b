// The actuation delay read from the force sensor (sensor_delay.hpp) on
// simulated sessions whose hidden delay the test knows and the fit does not:
// the simulation writes into the diagnosis' LogCollector as into a log.
#include <cmath>
#include <vector>

#include "hidden_case.hpp"
#include "manip/diagnosis/manipulandum.hpp"
#include "manip/diagnosis/sensor_delay.hpp"

#include <catch2/catch.hpp>

namespace manip::diagnosis {
namespace {

struct Run {
  SensorDelay sd;
  int perturbed = 0;
};

Run sensor_delay_of(const std::vector<sim::HiddenEffect>& effects, sim::NoiseLevel noise, std::uint64_t hidden_seed) {
  testing::Case c;
  c.effects = effects;
  c.noise = noise;
  c.hidden_seed = hidden_seed;
  c.movements = 60;
  auto cc = testing::collect_case(c);
  PlanarOptions po;
  po.pem_baseline = false;  // the sensor route needs the isolated signals only
  const auto prep = prepare_planar(cc.ses, po, 10);
  return {sensor_delay(prep.data, 100, 1), cc.sum.perturbed};
}

}  // namespace

// Measured (2026-12-06, 60 movements, seeds 5000-5008): the fit sits
// 0.026-0.036 ms below the hidden delay at 0, 1, 2 and 4 ms, noise-free and
// realistic; its bootstrap interval is ±0.005 ms wide, so it does not cover
// that offset (docs/diagnosis.md, "Actuation delay from the force sensor").
// The bound 0.06 ms is a quarter of a 4 kHz cycle; the kinematic likelihood's
// delay scatters by ±0.3 ms.
TEST_CASE("sensor delay: the hidden actuation delay within 0.06 ms, noise-free and realistic, beside friction - none for a clean session or a lagged sensor") {
  struct C {
    std::vector<sim::HiddenEffect> e;
    sim::NoiseLevel noise;
    std::uint64_t seed;
    double truth_s;
    double friction_n;
  };
  using M = sim::HiddenMechanism;
  const std::vector<C> cases = {
      {{}, sim::NoiseLevel::none, 5000, 0.0, 0.0},
      {{{M::actuation_delay, 0.004}}, sim::NoiseLevel::none, 5001, 0.004, 0.0},
      {{{M::actuation_delay, 0.002}, {M::stage_friction, 1.0}}, sim::NoiseLevel::realistic, 5005, 0.002, 1.0},
      // Both routes read the lagged sensor: no delay between them.
      {{{M::sensor_lag, 0.003}}, sim::NoiseLevel::realistic, 5008, 0.0, 0.0},
  };
  for (const auto& c : cases) {
    const auto r = sensor_delay_of(c.e, c.noise, c.seed);
    INFO("truth " << c.truth_s * 1e3 << " ms: tau " << r.sd.tau_s * 1e3 << " [" << r.sd.lo_s * 1e3 << ", " << r.sd.hi_s * 1e3 << "] ms, b "
                  << r.sd.mass_kg << ", F " << r.sd.friction_n << " at " << r.sd.friction_vs_mps << ", explained " << r.sd.explained_share
                  << ", trials " << r.sd.trials);
    REQUIRE(r.sd.available);
    CHECK(r.sd.trials == r.perturbed);
    CHECK(std::fabs(r.sd.tau_s - c.truth_s) < 0.00006);
    CHECK(r.sd.lo_s <= r.sd.tau_s);
    CHECK(r.sd.hi_s >= r.sd.tau_s);
    CHECK(r.sd.hi_s - r.sd.lo_s < 0.00005);
    if (c.truth_s > 0) CHECK(r.sd.explained_share > 0.9);
    if (c.friction_n > 0) {
      CHECK(r.sd.friction_n == Approx(c.friction_n).epsilon(0.1));
      CHECK(r.sd.friction_vs_mps == 0.001);  // the simulator's smoothing velocity (session_runner.cpp)
    } else {
      CHECK(std::fabs(r.sd.friction_n) < 0.05);  // 0 unless a positive friction explains a tenth of the residual
    }
  }
}

TEST_CASE("sensor delay: too few trials or no sensor signal - not available, saying why") {
  Dataset d;
  CHECK_FALSE(sensor_delay(d).available);
  CHECK(sensor_delay(d).why_not == "manipulandum sessions only");
  d.dt_s = 0.00025;
  PlanarTrial p;
  for (int k = 0; k < 100; ++k) {
    p.du_ext_adm.emplace_back(0.1 * k, 0.0);
    p.du_ext_force.emplace_back(0.0, 0.0);
    p.u_pert.emplace_back(0.0, 0.0);
    p.dxdd.emplace_back(0.0, 0.0);
  }
  p.u_pert_iso.assign(200, Eigen::Vector2d::Zero());
  p.u_pert_iso_pre = 100;
  for (int i = 0; i < 3; ++i) d.planar.push_back(p);
  auto r = sensor_delay(d);
  CHECK_FALSE(r.available);
  CHECK(r.why_not.find("has 3") != std::string::npos);
  d.planar.push_back(p);
  r = sensor_delay(d);
  CHECK_FALSE(r.available);
  CHECK(r.why_not.find("constant") != std::string::npos);
}

}  // namespace manip::diagnosis
