// The least-squares cores against exact, independently generated signals.
#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>

#include "manip/common/perturbation.hpp"
#include "manip/estimation/impedance.hpp"
#include "reference_arm.hpp"

using namespace manip;
using namespace manip::estimation;
using namespace manip::testutil;

namespace {


// Independent reference: RK4 at 64 kHz of the coupled arm + ideal admittance
// with the perturbation force held per 4 kHz sample.
struct Sim {
  std::vector<Vec2> x, xd, xdd, u;
};
Sim rk4(double angle, int n_samples, int onset) {
  PerturbationProfile p;
  const double fs = 4000.0;
  const int sub = 16;
  const double h = 1.0 / fs / sub;
  const Mat2 mt = kM + kMdev;
  Vec2 x = Vec2::Zero(), v = Vec2::Zero();
  Sim s;
  auto acc = [&](const Vec2& xx, const Vec2& vv, const Vec2& u) -> Vec2 {
    return mt.inverse() * (u - (kD + kDadm) * vv - kK * xx);
  };
  for (int k = 0; k < n_samples; ++k) {
    const Vec2 u = k >= onset ? p.force_n((k - onset) / fs, angle) : Vec2::Zero();
    s.x.push_back(x);
    s.xd.push_back(v);
    s.xdd.push_back(acc(x, v, u));
    s.u.push_back(u);
    for (int j = 0; j < sub; ++j) {
      const Vec2 a1 = acc(x, v, u), v1 = v;
      const Vec2 a2 = acc(x + 0.5 * h * v1, v + 0.5 * h * a1, u), v2 = v + 0.5 * h * a1;
      const Vec2 a3 = acc(x + 0.5 * h * v2, v + 0.5 * h * a2, u), v3 = v + 0.5 * h * a2;
      const Vec2 a4 = acc(x + h * v3, v + h * a3, u), v4 = v + h * a3;
      x += h / 6 * (v1 + 2 * v2 + 2 * v3 + v4);
      v += h / 6 * (a1 + 2 * a2 + 2 * a3 + a4);
    }
  }
  return s;
}

}  // namespace

TEST_CASE("equation error recovers D, K to 1e-6 from exact variational signals (eq. 30-32)") {
  std::vector<VariationalWindow> ws;
  std::vector<Mat2> ms;
  for (double deg : {30.0, 150.0, 240.0}) {
    const auto s = rk4(deg * std::numbers::pi / 180.0, 601, 0);
    VariationalWindow w;
    w.fs_hz = 4000;
    w.dx = s.x;
    w.dxd = s.xd;
    w.dxdd = s.xdd;
    w.u_pert = s.u;
    for (std::size_t k = 0; k < s.x.size(); ++k) {
      // Δu_ext exactly as eq. 21 defines it for this coupled system.
      w.du_ext_adm.push_back(s.u[k] - kMdev * s.xdd[k] - kDadm * s.xd[k]);
      w.du_ext_force.push_back(w.du_ext_adm.back());
    }
    ws.push_back(w);
    ms.push_back(kM);
  }
  SECTION("pooled, symmetric K") {
    const auto e = fit_equation_error(ws, ms, LsOptions{});
    CHECK((e.d_nspm - kD).norm() / kD.norm() < 1e-6);
    CHECK((e.k_npm - kK).norm() / kK.norm() < 1e-6);
    CHECK(e.vaf > 0.999999);
    CHECK(e.identifiable);
  }
  SECTION("single trial, full K and M estimated (eq. 24-29)") {
    LsOptions o;
    o.k_model = StiffnessModel::full;
    o.estimate_m = true;
    const auto e = fit_equation_error(std::span(ws.data(), 3), ms, o);
    CHECK((e.m_kg - kM).norm() / kM.norm() < 1e-6);
    CHECK((e.d_nspm - kD).norm() / kD.norm() < 1e-6);
    CHECK((e.k_npm - kK).norm() / kK.norm() < 1e-6);
  }
  SECTION("a single push direction is flagged as poorly identifiable") {
    std::vector<VariationalWindow> one{ws[0]};
    for (std::size_t k = 0; k < one[0].size(); ++k)  // tiny noise: the SE becomes meaningful
      one[0].du_ext_adm[k] += Vec2(1e-3 * std::sin(0.37 * k), 1e-3 * std::cos(0.91 * k));
    const auto e = fit_equation_error(one, std::span(ms.data(), 1), LsOptions{});
    CHECK(e.condition > 10.0);
  }
}

TEST_CASE("output error recovers D, K from an independently simulated movement + response") {
  // Measured position = smooth movement (cubic in time) + Δx from RK4.
  std::vector<OeWindow> ws;
  for (double deg : {30.0, 120.0, 210.0, 300.0}) {
    const int pre = 200, n = 801;
    const auto s = rk4(deg * std::numbers::pi / 180.0, n, pre);
    OeWindow w;
    w.fs_hz = 4000;
    w.onset_offset = pre;
    w.m_bsp_kg = kM;
    w.m_total_kg = kM + kMdev;
    w.d_adm_nspm = kDadm;
    for (int k = 0; k < n; ++k) {
      const double t = k / 4000.0;
      const Vec2 movement(0.001 * t - 0.002 * t * t, 0.35 + 0.12 * t + 0.3 * t * t - 0.2 * t * t * t);
      w.x_m.push_back(movement + s.x[static_cast<std::size_t>(k)]);
      w.u_n.push_back(s.u[static_cast<std::size_t>(k)]);
    }
    ws.push_back(w);
  }
  OeSettings o;
  o.poly_order = 3;
  const auto e = fit_output_error(ws, o);
  INFO("D = " << e.d_nspm << "\nK = " << e.k_npm);
  CHECK((e.d_nspm - kD).cwiseAbs().maxCoeff() < 1e-3 * kD.norm());
  CHECK((e.k_npm - kK).cwiseAbs().maxCoeff() < 1e-3 * kK.norm());
  CHECK(e.vaf > 0.999999);
  CHECK(e.se_kind == "jackknife over trials");
}

TEST_CASE("Student t quantiles") {
  CHECK(t_quantile_975(1) == Approx(12.706));
  CHECK(t_quantile_975(23) == Approx(2.069));
  CHECK(t_quantile_975(60) == Approx(2.000).epsilon(2e-3));
  CHECK(t_quantile_975(100000) == Approx(1.96).epsilon(1e-3));
}
