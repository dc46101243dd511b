// The neuromechanical arm's report figures (docs/simulation.md): max deviations
// under the 15 N pulse, the response per feedback configuration, tracking error,
// endpoint impedance and reflex gains at mid-reach. Prints text; not a test
// (moved out of tests/sim, where it was a hidden "[report]" case).
//
//   report_neuromech
#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <sstream>
#include <utility>
#include <vector>

#include "manip/common/perturbation.hpp"
#include "manip/sim/ideal_admittance.hpp"
#include "manip/sim/neuromech_arm.hpp"
#include "manip/sim/session_runner.hpp"

using namespace manip;
using namespace manip::sim;

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;

PlantParams test_plant() { return plant_params(default_sim_session()); }
void plant_step(HumanModel& human, const PlantParams& p, const Vec2& u, double dt_s) {
  step_ideal_admittance(human, p, u, dt_s, true);
}

struct Trial {
  std::vector<Vec2> x;     // hand, per plant sample (before the step)
  std::vector<Vec2> plan;  // planned hand position, same samples
  long onset{-1};          // sample at which the perturbation started
};

// One reach at fs with the pulse from the first sample at or beyond x2 = 0.40 m
// (paper §4.2). amplitude 0 = unperturbed.
Trial run_trial(NeuromechanicalArm& arm, const ReachSpec& reach, std::uint64_t seed, double amplitude_n,
                double angle_rad, double fs_hz = 4000.0, double extra_s = 0.5) {
  const PlantParams plant = test_plant();
  PerturbationProfile prof;
  prof.amplitude_n = amplitude_n;
  arm.begin_trial(reach, seed);
  const double dt = 1.0 / fs_hz;
  const auto n = static_cast<long>(std::ceil((reach.t_start_s + reach.duration_s + extra_s) * fs_hz));
  Trial out;
  for (long k = 0; k < n; ++k) {
    const Vec2 x = arm.hand_position_m();
    if (out.onset < 0 && x.y() >= 0.40) out.onset = k;
    out.x.push_back(x);
    out.plan.push_back(arm.planned_hand_position_m());
    const Vec2 u = out.onset >= 0 ? prof.force_n(static_cast<double>(k - out.onset) * dt, angle_rad) : Vec2::Zero();
    plant_step(arm, plant, u, dt);
  }
  return out;
}

Vec2 max_deviation(const Trial& pert, const Trial& twin, double fs_hz = 4000.0, double window_s = 0.15) {
  Vec2 m = Vec2::Zero();
  const auto n = static_cast<long>(std::lround(window_s * fs_hz));
  for (long k = pert.onset; k <= pert.onset + n; ++k)
    m = m.cwiseMax((pert.x[static_cast<std::size_t>(k)] - twin.x[static_cast<std::size_t>(k)]).cwiseAbs());
  return m;
}

NeuromechParams quiet(NeuromechParams p) {
  p.noise_cv = 0.0;
  p.noise_floor_n = 0.0;
  return p;
}

Eigen::Vector2d sym_eig(const Mat2& m) {
  return Eigen::SelfAdjointEigenSolver<Mat2>(0.5 * (m + m.transpose())).eigenvalues();
}

}  // namespace

int main() {
  // Max deviations under the 15 N pulse, paper configuration, with and without noise.
  for (const bool noise : {false, true}) {
    NeuromechParams p = noise ? NeuromechParams{} : quiet(NeuromechParams{});
    NeuromechanicalArm arm(p);
    std::vector<double> d1, d2;
    int seed = 0;
    for (const double angle : {30.0, 60.0, 120.0, 150.0, 210.0, 240.0, 300.0, 330.0}) {
      ReachSpec r;
      const Trial twin = run_trial(arm, r, static_cast<std::uint64_t>(++seed), 0.0, angle * kDeg);
      const Trial pert = run_trial(arm, r, static_cast<std::uint64_t>(seed), 15.0, angle * kDeg);
      const Vec2 dev = max_deviation(pert, twin);
      d1.push_back(dev(0) * 1e3);
      d2.push_back(dev(1) * 1e3);
      std::printf("paper config, noise %d, angle %5.0f: max dev x1 %.2f mm x2 %.2f mm\n", noise, angle, dev(0) * 1e3,
                  dev(1) * 1e3);
    }
    const auto ms = [](const std::vector<double>& v) {
      double m = 0, s = 0;
      for (double x : v) m += x;
      m /= static_cast<double>(v.size());
      for (double x : v) s += (x - m) * (x - m);
      return std::pair{m, std::sqrt(s / static_cast<double>(v.size() - 1))};
    };
    const auto [m1, s1] = ms(d1);
    const auto [m2, s2] = ms(d2);
    std::printf("paper config, noise %d: mean (std) max dev x1 %.2f (%.2f) mm, x2 %.2f (%.2f) mm\n", noise, m1, s1, m2, s2);
  }
  // Time course of the response to the pulse, per feedback configuration.
  for (int cfg = 0; cfg < 4; ++cfg) {
    NeuromechParams p = quiet(NeuromechParams{});
    p.pathway(Pathway::kShortLatency).enabled = cfg == 2 || cfg == 3;
    p.pathway(Pathway::kLongLatency).enabled = cfg == 1 || cfg == 3;
    p.pathway(Pathway::kVoluntary).enabled = cfg == 3;
    NeuromechanicalArm arm(p);
    ReachSpec r;
    const Trial twin = run_trial(arm, r, 5, 0.0, 150 * kDeg, 4000.0, 1.0);
    const Trial pert = run_trial(arm, r, 5, 15.0, 150 * kDeg, 4000.0, 1.0);
    std::printf("config %d response |dx| [mm] every 100 ms after onset:", cfg);
    for (std::size_t k = static_cast<std::size_t>(pert.onset); k < pert.x.size(); k += 400)
      std::printf(" %.2f", (pert.x[k] - twin.x[k]).norm() * 1e3);
    std::printf("\n");
  }
  // Tracking error of the unperturbed reach with noise (paper configuration).
  {
    NeuromechanicalArm arm(NeuromechParams{});
    double worst = 0.0, end = 0.0;
    for (std::uint64_t seed = 1; seed <= 10; ++seed) {
      const Trial t = run_trial(arm, ReachSpec{}, seed, 0.0, 0.0);
      for (std::size_t k = 0; k < t.x.size(); ++k) worst = std::max(worst, (t.x[k] - t.plan[k]).norm());
      end = std::max(end, (t.x.back() - t.plan.back()).norm());
    }
    std::printf("paper config with noise, 10 reaches: max |x - plan| %.3f mm, at the end %.3f mm\n", worst * 1e3,
                end * 1e3);
  }
  // Endpoint impedance at mid-reach (x2 = 0.40 m), intrinsic only, and the reflex gains.
  {
    NeuromechParams p = quiet(NeuromechParams{});
    for (auto& f : p.feedback) f.enabled = true;
    NeuromechanicalArm arm(p);
    arm.begin_trial(ReachSpec{}, 1);
    const PlantParams plant = test_plant();
    while (arm.hand_position_m().y() < 0.40) plant_step(arm, plant, Vec2::Zero(), 0.25e-3);
    Mat2 d, k, d_s, k_s;
    arm.endpoint_impedance(d, k);
    arm.endpoint_impedance_eq16_18(d_s, k_s);
    const auto pr = [](const char* what, const Mat2& m) {
      const auto e = sym_eig(m);
      std::printf("%-28s [[%8.2f %8.2f] [%8.2f %8.2f]]  sym eig %.1f %.1f\n", what, m(0, 0), m(0, 1), m(1, 0), m(1, 1),
                  e(0), e(1));
    };
    std::printf("at x = (%.3f, %.3f) m, t = %.3f s, M_x:\n", arm.hand_position_m()(0), arm.hand_position_m()(1),
                arm.time_s());
    Mat2 m_x;
    Vec2 h;
    arm.endpoint_dynamics(m_x, h);
    pr("M_x [kg]", m_x);
    pr("K full [N/m]", k);
    pr("K eq.18 [N/m]", k_s);
    pr("D full [Ns/m]", d);
    pr("D eq.17 [Ns/m]", d_s);
    for (int i = 0; i < kPathways; ++i) {
      arm.reflex_endpoint_gains(static_cast<Pathway>(i), d, k);
      std::printf("%s (%.0f ms):\n", pathway_name(static_cast<Pathway>(i)), p.feedback[static_cast<std::size_t>(i)].delay_s * 1e3);
      pr("  K reflex [N/m]", k);
      pr("  D reflex [Ns/m]", d);
    }
    std::printf("activations [N]: %s\n", [&] {
      std::ostringstream s;
      s << arm.activations_n().transpose();
      return s.str();
    }().c_str());
  }
  return 0;
}
