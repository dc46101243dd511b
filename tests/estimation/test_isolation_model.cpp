// Tests of the model-based isolation (include/manip/estimation/isolation_model.hpp)
// against closed-form and independently integrated references.
#include <catch2/catch.hpp>

#include <cmath>
#include <numbers>
#include <vector>

#include "manip/common/perturbation.hpp"
#include "manip/estimation/isolation_model.hpp"
#include "manip/estimation/validation.hpp"
#include "manip/model/arm.hpp"

using namespace manip;
using namespace manip::estimation;

TEST_CASE("isolation: model response equals the closed-form step response of a damped oscillator") {
  // Diagonal system, constant force on x1 from onset: per axis
  //   m x'' + c x' + k x = u  =>  x = u/k (1 - e^(-s t) (cos w t + s/w sin w t)),
  //   x' = u/k (w0^2 / w) e^(-s t) sin w t,  s = c / 2m, w0^2 = k/m, w^2 = w0^2 - s^2.
  const double m = 7.0, c_arm = 10.0, c_adm = 15.0, k = 300.0, u = 2.0, fs = 4000.0;
  OeWindow w;
  w.fs_hz = fs;
  w.onset_offset = 40;
  w.m_total_kg = Mat2::Identity() * m;
  w.d_adm_nspm = Mat2::Identity() * c_adm;
  const std::size_t n = 800;
  w.x_m.assign(n, Vec2::Zero());
  w.u_n.assign(n, Vec2::Zero());
  for (std::size_t i = 40; i < n; ++i) w.u_n[i] = Vec2(u, 0.0);
  const auto r = simulate_variational_states(w, Mat2::Identity() * c_arm, Mat2::Identity() * k);
  const double s = (c_arm + c_adm) / (2 * m), w0 = std::sqrt(k / m), wd = std::sqrt(w0 * w0 - s * s);
  const auto x_at = [&](double t) { return u / k * (1 - std::exp(-s * t) * (std::cos(wd * t) + s / wd * std::sin(wd * t))); };
  const auto v_at = [&](double t) { return u / k * (w0 * w0 / wd) * std::exp(-s * t) * std::sin(wd * t); };
  double worst_x = 0, worst_v = 0, worst_a = 0;
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const double t = (static_cast<double>(i) - 40.0) / fs;
    const double xe = t > 0 ? x_at(t) : 0.0, ve = t > 0 ? v_at(t) : 0.0;
    const double ae = i >= 40 ? (v_at(t + 1 / fs) - ve) * fs : 0.0;  // velocity change over the cycle
    worst_x = std::max(worst_x, std::abs(r.x[i].x() - xe) / (u / k));
    worst_v = std::max(worst_v, std::abs(r.xd[i].x() - ve));
    worst_a = std::max(worst_a, std::abs(r.xdd[i].x() - ae));
    CHECK(r.x[i].y() == 0.0);
  }
  INFO("max errors: x " << worst_x << " (relative), v " << worst_v << " m/s, a " << worst_a << " m/s^2");
  CHECK(worst_x < 1e-9);
  CHECK(worst_v < 1e-10);
  CHECK(worst_a < 1e-7);
}

namespace {

// The linear variational model integrated by classical RK4 with 16 sub-steps per
// sample (independent of the matrix exponential the isolation uses), force held per sample.
std::vector<Vec2> rk4_response(const Mat2& m_tot, const Mat2& d_tot, const Mat2& k, const std::vector<Vec2>& u,
                               double fs) {
  const Mat2 minv = m_tot.inverse();
  Vec2 x = Vec2::Zero(), v = Vec2::Zero();
  std::vector<Vec2> out;
  const int sub = 16;
  const double h = 1.0 / (fs * sub);
  for (const Vec2& ui : u) {
    out.push_back(x);
    const auto acc = [&](const Vec2& xx, const Vec2& vv) -> Vec2 { return minv * (ui - d_tot * vv - k * xx); };
    for (int j = 0; j < sub; ++j) {
      const Vec2 k1x = v, k1v = acc(x, v);
      const Vec2 k2x = v + 0.5 * h * k1v, k2v = acc(x + 0.5 * h * k1x, v + 0.5 * h * k1v);
      const Vec2 k3x = v + 0.5 * h * k2v, k3v = acc(x + 0.5 * h * k2x, v + 0.5 * h * k2v);
      const Vec2 k4x = v + h * k3v, k4v = acc(x + h * k3x, v + h * k3v);
      x += h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
      v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
    }
  }
  return out;
}

}  // namespace

TEST_CASE("isolation: a synthetic session's variational response and impedance are recovered") {
  // 16 trials (8 directions x 2) of a linear arm (D, K known) on the admittance,
  // during a smooth reach, 1 um quantisation. The model-based isolation must recover
  // Δx, Δẋ, Δẍ and Δu_ext far better than the paper's high-pass isolation.
  SessionInfo info;
  info.m_handle_kg = Vec2(0.3, 0.3);
  const double fs = info.sample_rate_hz;
  Mat2 d_true, k_true;
  d_true << 12.0, -5.0, -4.0, 14.0;
  k_true << 150.0, -60.0, -60.0, 170.0;
  const TwoLinkArm arm(info.anthropometrics);
  const PerturbationProfile prof;
  std::vector<TrialData> trials;
  const std::size_t n = 8000, on = 4000;  // 2 s, onset at 1 s
  int trial_no = 0;
  for (int rep = 0; rep < 2; ++rep)
    for (const double deg : {30.0, 60.0, 120.0, 150.0, 210.0, 240.0, 300.0, 330.0}) {
      TrialData t;
      t.trial = trial_no++;
      t.perturbed = true;
      t.angle_rad = deg * std::numbers::pi / 180.0;
      t.amplitude_n = 15.0;
      t.onset_index = static_cast<std::int64_t>(on);
      t.ended = true;
      // Unperturbed movement: a minimum-jerk reach along x2 over 2.4 s (through 0.40 m at onset).
      std::vector<Vec2> x0(n), v0(n), a0(n), u(n, Vec2::Zero());
      for (std::size_t i = 0; i < n; ++i) {
        const double tau = std::clamp((static_cast<double>(i) / fs - 0.0) / 2.0, 0.0, 1.0);
        const double L = 0.2 + 0.01 * rep;
        x0[i] = Vec2(0.002 * std::sin(1.3 * static_cast<double>(i) / fs), 0.30 + L * (10 * std::pow(tau, 3) - 15 * std::pow(tau, 4) + 6 * std::pow(tau, 5)));
        v0[i] = Vec2(0.0026 * std::cos(1.3 * static_cast<double>(i) / fs), L / 2.0 * (30 * tau * tau - 60 * std::pow(tau, 3) + 30 * std::pow(tau, 4)));
        if (i >= on) u[i] = prof.force_n(static_cast<double>(i - on) / fs, t.angle_rad);
      }
      const Mat2 m_bsp = *arm.endpoint_inertia_at(x0[on]);
      const Mat2 m_tot = m_bsp + info.m_adm_shoulder_kg() + info.m_handle_shoulder_kg();
      std::vector<Vec2> u_win(u.begin() + static_cast<std::ptrdiff_t>(on), u.end());
      const auto dx = rk4_response(m_tot, d_true + info.d_adm_shoulder_nspm(), k_true, u_win, fs);
      for (std::size_t i = 0; i < n; ++i) {
        const Vec2 dxi = i >= on ? dx[i - on] : Vec2::Zero();
        const Vec2 xi = x0[i] + dxi;
        t.x_m.push_back(Vec2(std::round(xi.x() * 1e6) * 1e-6, std::round(xi.y() * 1e6) * 1e-6));
        t.x_ref_m.push_back(xi);
        t.x_twin_m.push_back(x0[i]);
        t.f_sensor_n.push_back(Vec2::Zero());
        t.u_pert_n.push_back(u[i]);
      }
      // Velocities and per-cycle accelerations by differences of the exact positions (truth for the NRMSE).
      for (std::size_t i = 0; i < n; ++i) {
        const std::size_t j = std::min(i + 1, n - 1), jj = std::min(i + 2, n - 1);
        t.xd_ref_m.push_back((t.x_ref_m[j] - t.x_ref_m[i]) * fs);
        t.xd_twin_m.push_back((t.x_twin_m[j] - t.x_twin_m[i]) * fs);
        t.xdd_ref_m.push_back((t.x_ref_m[jj] - 2 * t.x_ref_m[j] + t.x_ref_m[i]) * fs * fs);
        t.xdd_twin_m.push_back((t.x_twin_m[jj] - 2 * t.x_twin_m[j] + t.x_twin_m[i]) * fs * fs);
      }
      trials.push_back(std::move(t));
    }
  ModelIsolationSettings s;
  const auto iso = isolate_model_based(info, trials, s);
  REQUIRE(iso.windows.size() == trials.size());
  INFO("D " << iso.d_session_nspm << "\nK " << iso.k_session_npm);
  CHECK((iso.d_session_nspm - d_true).norm() < 0.05 * d_true.norm());
  CHECK((iso.k_session_npm - k_true).norm() < 0.05 * k_true.norm());
  // Against the exact response (not the difference-based truth): max error / peak.
  double worst = 0.0;
  for (const auto& w : iso.windows) {
    double peak = 0.0, err = 0.0;
    for (std::size_t i = 0; i < w.size(); ++i) {
      peak = std::max(peak, w.dx_true[i].norm());
      err = std::max(err, (w.dx[i] - w.dx_true[i]).norm());
    }
    worst = std::max(worst, err / peak);
  }
  INFO("worst max |Δx error| / peak over trials " << worst);
  CHECK(worst < 0.02);
  // Fig. 4 NRMSE at 150 ms, model-based vs the paper's isolation on the same trials.
  const auto c = nrmse_curves(iso.windows, 0.15, 30, "model-based");
  std::vector<VariationalWindow> paper;
  for (const auto& t : trials) paper.push_back(isolate_variational(info, t, PipelineSettings{}));
  const auto cp = nrmse_curves(paper);
  for (int sig = 0; sig < 4; ++sig) {
    INFO("signal " << NrmseCurves::kSignals[static_cast<std::size_t>(sig)] << ": model " << c.mean[static_cast<std::size_t>(sig)].back().transpose()
                   << ", paper " << cp.mean[static_cast<std::size_t>(sig)].back().transpose());
    CHECK(c.mean[static_cast<std::size_t>(sig)].back().maxCoeff() < 0.02);
    CHECK(c.mean[static_cast<std::size_t>(sig)].back().maxCoeff() < cp.mean[static_cast<std::size_t>(sig)].back().maxCoeff());
  }
}
