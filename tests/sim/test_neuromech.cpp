// Tests of the neuromechanical arm (include/manip/sim/neuromech_arm.hpp).
#include <catch2/catch.hpp>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <unsupported/Eigen/MatrixFunctions>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <new>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "alloc_counter.hpp"
#include "fixtures.hpp"
#include "manip/common/rng.hpp"
#include "manip/common/perturbation.hpp"
#include "manip/sim/min_jerk.hpp"
#include "manip/sim/ideal_admittance.hpp"
#include "manip/sim/neuromech_arm.hpp"
#include "manip/sim/session_runner.hpp"

using namespace manip;
using namespace manip::sim;

namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
const std::string kConfig = std::string(MANIP_SOURCE_DIR) + "/config/arm_model.yaml";

// The ideal admittance of eq. 19-20 as the session describes it (schema
// defaults: 5 kg, 15 Ns/m, 0.25 kg handle), stepped by the library's plant step;
// midpoint by default (the session runner's plant for the neuromechanical arm).
PlantParams test_plant() { return plant_params(default_sim_session()); }
Vec2 plant_step(HumanModel& human, const PlantParams& p, const Vec2& u_pert_n, double dt_s, bool midpoint = true) {
  return step_ideal_admittance(human, p, u_pert_n, dt_s, midpoint).xdd_mps2;
}

struct Trial {
  std::vector<Vec2> x;    // hand, per plant sample (before the step)
  std::vector<Vec2> plan;  // planned hand position, same samples
  long onset{-1};          // sample at which the perturbation started
};

// One reach on the test plant at fs with the perturbation triggered when the hand
// first crosses x2 = 0.40 m (paper §4.2). amplitude 0 = unperturbed.
// forced_onset >= 0: start the perturbation at that sample instead.
Trial run_trial(NeuromechanicalArm& arm, const ReachSpec& reach, std::uint64_t seed, double amplitude_n,
                double angle_rad, double fs_hz = 4000.0, double extra_s = 0.5, long forced_onset = -1) {
  const PlantParams plant = test_plant();
  PerturbationProfile prof;
  prof.amplitude_n = amplitude_n;
  arm.begin_trial(reach, seed);
  const double dt = 1.0 / fs_hz;
  const auto n = static_cast<long>(std::ceil((reach.t_start_s + reach.duration_s + extra_s) * fs_hz));
  Trial out;
  out.x.reserve(static_cast<std::size_t>(n));
  out.plan.reserve(static_cast<std::size_t>(n));
  for (long k = 0; k < n; ++k) {
    const Vec2 x = arm.hand_position_m();
    if (out.onset < 0 && (forced_onset >= 0 ? k == forced_onset : x.y() >= 0.40)) out.onset = k;
    out.x.push_back(x);
    out.plan.push_back(arm.planned_hand_position_m());
    const Vec2 u = out.onset >= 0 ? prof.force_n(static_cast<double>(k - out.onset) * dt, angle_rad) : Vec2::Zero();
    plant_step(arm, plant, u, dt);
  }
  return out;
}

// Max |dx1|, |dx2| of perturbed - twin over [onset, onset + window].
Vec2 max_deviation(const Trial& pert, const Trial& twin, double fs_hz = 4000.0, double window_s = 0.15) {
  Vec2 m = Vec2::Zero();
  const auto n = static_cast<long>(std::lround(window_s * fs_hz));
  for (long k = pert.onset; k <= pert.onset + n; ++k) {
    const Vec2 d = pert.x[static_cast<std::size_t>(k)] - twin.x[static_cast<std::size_t>(k)];
    m = m.cwiseMax(d.cwiseAbs());
  }
  return m;
}

NeuromechParams quiet(NeuromechParams p) {  // no noise
  p.noise_cv = 0.0;
  p.noise_floor_n = 0.0;
  return p;
}

NeuromechParams passive() {  // no muscles, no feedback, no noise: a free two-link arm
  NeuromechParams p = quiet(NeuromechParams{});
  p.k0_npm.setZero();
  p.k1_per_m.setZero();
  p.tonic_activation_n.setZero();
  p.feedforward_enabled = false;
  p.disable_feedback();
  return p;
}

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Writes the shipped config with `from` replaced by `to` and returns the loader's message.
std::string load_error(const std::string& from, const std::string& to) {
  std::string text = read_text(kConfig);
  const auto pos = text.find(from);
  REQUIRE(pos != std::string::npos);
  text.replace(pos, from.size(), to);
  const std::string path = testutil::temp_dir("neuromech_cfg") + "/arm.yaml";
  std::ofstream(path) << text;
  try {
    (void)load_neuromech_params(path);
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    CHECK(msg.find('\n') == std::string::npos);  // one line
    CHECK(msg.rfind(path, 0) == 0);               // starts with the file name
    return msg;
  }
  FAIL("no error for " << to);
  return {};
}

Vec2 u_ext(const NeuromechanicalArm& arm, const Vec2& x, const Vec2& xd) {  // M_x xdd* - h at (x, xd)
  Mat2 m_x;
  Vec2 h;
  arm.endpoint_dynamics_at(x, xd, m_x, h);
  return m_x * arm.last_hand_acceleration_mps2() - h;
}

// Central differences of u_ext = M_x(x) xdd* - h(x, xd) w.r.t. hand position and velocity.
void fd_impedance(const NeuromechanicalArm& arm, Mat2& d_fd, Mat2& k_fd) {
  const Vec2 x = arm.hand_position_m(), xd = arm.hand_velocity_mps();
  const double ex = 1e-6, ev = 1e-6;
  for (int j = 0; j < 2; ++j) {
    const Vec2 dx = Vec2::Unit(j) * ex, dv = Vec2::Unit(j) * ev;
    k_fd.col(j) = (u_ext(arm, x + dx, xd) - u_ext(arm, x - dx, xd)) / (2 * ex);
    d_fd.col(j) = (u_ext(arm, x, xd + dv) - u_ext(arm, x, xd - dv)) / (2 * ev);
  }
}

Eigen::Vector2d sym_eig(const Mat2& m) {
  return Eigen::SelfAdjointEigenSolver<Mat2>(0.5 * (m + m.transpose())).eigenvalues();
}

}  // namespace

TEST_CASE("neuromech: the shipped config loads, equals the built-in defaults and round-trips") {
  const NeuromechParams p = load_neuromech_params(kConfig);
  CHECK(p == NeuromechParams{});
  CHECK_FALSE(p.invalid_reason());
  const std::string path = testutil::temp_dir("neuromech_rt") + "/arm.yaml";
  NeuromechParams q = p;
  q.tonic_activation_n(3) = 12.345678901234567;
  q.pathway(Pathway::kVoluntary).enabled = true;
  std::ofstream(path) << neuromech_params_to_yaml(q);
  CHECK(load_neuromech_params(path) == q);
}

TEST_CASE("neuromech: invalid config values and keys are rejected with file, key and reason") {
  using Catch::Matchers::Contains;
  CHECK_THAT(load_error("mass_kg: 1.93", "mass_kg: -1.93"), Contains("anthropometrics.upper_arm.mass_kg"));
  CHECK_THAT(load_error("inertia_kgm2: 0.0188", "inertia_kgm2: 0.0"), Contains("anthropometrics.forearm.inertia_kgm2"));
  CHECK_THAT(load_error("delay_s: 0.060", "delay_s: 0.0601"),
             Contains("feedback.long_latency.delay_s") && Contains("whole number of simulation steps"));
  CHECK_THAT(load_error("long_latency:  {enabled: true,  delay_s: 0.060", "long_latency:  {enabled: true,  delay_s: 0.0"),
             Contains("feedback.long_latency.delay_s") && Contains("at least one simulation step"));
  CHECK_THAT(load_error("  tau_s: 0.05", "  tau_s: 0.05\n  sigma: 1.0"), Contains("noise.sigma") && Contains("unknown key"));
  CHECK_THAT(load_error("  floor_n: 0.0\n", ""), Contains("noise.floor_n") && Contains("missing"));
  // The common strict reader: a key given twice is refused with its line (file:line: key: reason).
  CHECK_THAT(load_error("  tau_s: 0.05", "  tau_s: 0.05\n  tau_s: 0.06"),
             Contains("arm.yaml:112: noise.tau_s: duplicate key"));
  CHECK_THAT(load_error("  tau_s: 0.05", "  tau_s: -0.05"), Contains("noise.tau_s") && Contains("must be positive"));
  CHECK_THAT(load_error("step_s: 6.25e-05", "step_s: fast"), Contains("integration.step_s") && Contains("expected a finite number"));
  CHECK_THAT(load_error("session_step_s: 2.5e-04", "session_step_s: 0.0"),
             Contains("integration.session_step_s") && Contains("must be in"));
  CHECK_THAT(load_error("session_step_s: 2.5e-04", "session_step_s: 3.0e-04"),  // 25 ms is not 83.3 steps
             Contains("feedback.short_latency.delay_s") && Contains("session steps"));
  CHECK_THAT(load_error("k1_per_m: [75.0, 75.0, 75.0, 75.0, 75.0, 75.0]", "k1_per_m: [75.0, 75.0]"),
             Contains("muscles.k1_per_m") && Contains("expected 6 numbers"));
  CHECK_THAT(load_error("k0_npm:   [810.8,", "k0_npm:   [-810.8,"), Contains("muscles.k0_npm") && Contains("shoulder_flexor"));
  CHECK_THAT(load_error("shoulder: [0.0536, -0.0536, 0.0,    0.0,    0.0386, -0.0388]",
                        "shoulder: [0.0536, 0.0536, 0.0,    0.0,    0.0386, 0.0388]\n    elbow:    [0.0,    0.0,     0.0316, 0.0267, 0.0427, 0.0300]\n    unused:"),
             Contains("muscles.moment_arms_m"));
  CHECK_THAT(load_error("stiffness_to_damping_per_s: 12.0", "stiffness_to_damping_per_s: 0"),
             Contains("muscles.stiffness_to_damping_per_s"));
  CHECK_THAT(load_error("kd_nspm: 300.0", "kd_nspm: -1"), Contains("feedback.voluntary.kd_nspm"));
  CHECK_THAT(load_error("enabled: true\n  load_mass_kg", "enabled: maybe\n  load_mass_kg"),
             Contains("feedforward.enabled"));

  // Moment arms whose columns all lie in one half-plane cannot produce every torque.
  NeuromechParams p;
  p.moment_arms_m.row(0) = p.moment_arms_m.row(0).cwiseAbs();
  p.moment_arms_m.row(1) = p.moment_arms_m.row(1).cwiseAbs();
  REQUIRE(p.invalid_reason());
  CHECK_THAT(*p.invalid_reason(), Contains("muscles.moment_arms_m"));
  CHECK_THROWS_AS(NeuromechanicalArm(p), std::invalid_argument);
}

TEST_CASE("neuromech: the motor-noise source (PortableRng::normal) is standard normal and deterministic per seed") {
  PortableRng g(12345);
  const int n = 2'000'000;
  const double z[] = {-4.0, -3.5, -3.0, -2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0, 3.0, 3.5, 4.0};
  std::vector<long> below(std::size(z), 0);
  double sum = 0.0, sum2 = 0.0, sum4 = 0.0;
  for (int i = 0; i < n; ++i) {
    const double x = g.normal();
    sum += x;
    sum2 += x * x;
    sum4 += x * x * x * x;
    for (std::size_t j = 0; j < std::size(z); ++j) below[j] += x < z[j] ? 1 : 0;
  }
  const double mean = sum / n, var = sum2 / n - mean * mean;
  CHECK(std::abs(mean) < 4.0 / std::sqrt(n));
  CHECK(std::abs(var - 1.0) < 4.0 * std::sqrt(2.0 / n));
  CHECK(sum4 / n == Approx(3.0).epsilon(0.01));  // kurtosis: the tails are right
  for (std::size_t j = 0; j < std::size(z); ++j) {
    const double p = 0.5 * std::erfc(-z[j] / std::sqrt(2.0));
    const double se = std::sqrt(p * (1 - p) / n);
    INFO("P(x < " << z[j] << ") = " << static_cast<double>(below[j]) / n << ", expected " << p);
    CHECK(std::abs(static_cast<double>(below[j]) / n - p) < 5.0 * se + 1e-7);
  }
  PortableRng a(7), b(7);
  bool same = true;
  for (int i = 0; i < 1000; ++i) same = same && a.normal() == b.normal();
  CHECK(same);
  b.seed(8);
  CHECK(a.normal() != b.normal());
}

TEST_CASE("neuromech: endpoint dynamics agree with TwoLinkArm (eq. 1-2, 16)") {
  // The model caches its own trigonometry per posture; the reference here is built
  // from TwoLinkArm and the model's muscle tensions.
  NeuromechanicalArm arm(NeuromechParams{});
  const TwoLinkArm& ref = arm.arm();
  for (const auto& [q, qd] : {std::pair{Vec2(0.6, 1.4), Vec2(1.2, -1.8)}, std::pair{Vec2(0.2, 2.1), Vec2(-0.3, 0.4)}}) {
    arm.set_joint_state(JointState{q, qd});
    Mat2 m_x;
    Vec2 h;
    arm.endpoint_dynamics(m_x, h);
    const Mat2 jinv = ref.jacobian(q).inverse();
    const Vec2 tau = arm.params().moment_arms_m * arm.tensions_n();
    const Vec2 h_ref = jinv.transpose() * (tau - ref.coriolis(q, qd)) + ref.endpoint_inertia(q) * (ref.jacobian_dot(q, qd) * qd);
    CHECK((arm.hand_position_m() - ref.hand_position_m(q)).norm() < 1e-14);
    CHECK((arm.hand_velocity_mps() - ref.jacobian(q) * qd).norm() < 1e-14);
    CHECK((m_x - ref.endpoint_inertia(q)).norm() < 1e-12 * m_x.norm());
    CHECK((h - h_ref).norm() < 1e-12 * (1.0 + h.norm()));
    // advance() imposes the hand acceleration: qdd = J^-1 (xdd - Jd qd).
    const Vec2 xdd(0.7, -1.1);
    const double dt = arm.params().step_s;
    const Vec2 qdd = jinv * (xdd - ref.jacobian_dot(q, qd) * qd);
    arm.advance(dt, xdd);
    CHECK((arm.joint_state().qd_radps - (qd + dt * qdd)).norm() < 1e-13);
    CHECK((arm.joint_state().q_rad - (q + dt * qd + 0.5 * dt * dt * qdd)).norm() < 1e-13);  // exact for held qdd
  }
  // The plan's posture (algebraic inverse kinematics) agrees with TwoLinkArm's.
  ReachSpec r;
  r.lateral_bow_m = 0.02;
  arm.begin_trial(r, 1);
  for (int n = 0; n < 16000; ++n) {
    arm.advance(4 * arm.params().step_s, Vec2::Zero());
    if (n % 1000 != 0) continue;
    const JointState pl = arm.planned_joint_state();
    const auto q_ref = ref.inverse_kinematics(arm.planned_hand_position_m());
    REQUIRE(q_ref);
    CHECK((pl.q_rad - *q_ref).norm() < 1e-12);
    const auto s = min_jerk(r.start_shoulder_m, r.goal_shoulder_m, r.t_start_s, r.duration_s, r.lateral_bow_m, arm.time_s());
    CHECK((ref.jacobian(pl.q_rad) * pl.qd_radps - s.xd).norm() < 1e-12);
  }
}

TEST_CASE("neuromech: the passive arm conserves energy under its integrator") {
  // Free motion (no muscles, u_ext = 0): only velocity-product forces, which do no
  // work, so E = 1/2 qd^T M_q qd is constant. A free two-link arm always ends up
  // swinging through the straight-arm singularity (its effective potential in q2 is
  // lowest there), so the free run is 2 s from a state that stays folded.
  // Semi-implicit Euler is first order: the energy error oscillates with amplitude
  // O(step) instead of growing. Accepted: max |E - E0| / E0 < 2e-4 at 16 kHz for
  // joint speeds of ~1 rad/s (faster than the protocol's 3 s reaches; measured
  // 1.1e-4), and halving the step halves it (integration error, not a defect of the
  // model's forces).
  const auto max_rel_error = [](double step_s) {
    NeuromechParams p = passive();
    p.step_s = step_s;
    NeuromechanicalArm arm(p);
    JointState s;
    s.q_rad = Vec2(0.5, 2.0);
    s.qd_radps = Vec2(-1.0, 1.0);
    arm.set_joint_state(s);
    const double e0 = arm.kinetic_energy_j();
    double worst = 0.0, q2_min = 10.0, q2_max = -10.0;
    const auto n = static_cast<long>(std::lround(2.0 / step_s));
    for (long k = 0; k < n; ++k) {
      Mat2 m_x;
      Vec2 h;
      arm.endpoint_dynamics_for_step(step_s, m_x, h);
      arm.advance(step_s, m_x.inverse() * h);
      worst = std::max(worst, std::abs(arm.kinetic_energy_j() - e0) / e0);
      q2_min = std::min(q2_min, arm.joint_state().q_rad(1));
      q2_max = std::max(q2_max, arm.joint_state().q_rad(1));
    }
    REQUIRE(q2_min > 0.5);  // stayed clear of the straight-arm singularity
    REQUIRE(q2_max < 3.0);
    return worst;
  };
  const double e16 = max_rel_error(1.0 / 16000.0);
  const double e32 = max_rel_error(1.0 / 32000.0);
  INFO("free arm: max relative energy error 16 kHz " << e16 << ", 32 kHz " << e32);
  CHECK(e16 < 2e-4);
  CHECK(e32 < 0.6 * e16);
}

TEST_CASE("neuromech: undamped muscle springs about a fixed posture conserve energy over 10 s") {
  // Balanced tonic co-contraction, no feed-forward torque, no feedback, no noise,
  // D_m ~ 0: tau = -A diag(K_m) A^T (q - q_d), a conservative field with potential
  // V = 1/2 dq^T K_q dq. The arm oscillates about q_d, far from any singularity, so
  // the integrator can be checked over a long run: no secular drift.
  NeuromechParams p = quiet(NeuromechParams{});
  p.disable_feedback();
  p.feedforward_enabled = false;
  p.stiffness_to_damping_per_s = 1e12;
  NeuromechanicalArm arm(p);
  ReachSpec still;
  still.goal_shoulder_m = still.start_shoulder_m;  // a plan that stays put
  arm.begin_trial(still, 1);
  const Vec2 q_d = arm.joint_state().q_rad;
  const auto& A = p.moment_arms_m;
  const Mat2 kq = A * (p.k0_npm + p.k1_per_m.cwiseProduct(arm.activations_n())).asDiagonal() * A.transpose();
  JointState s;
  s.q_rad = q_d + Vec2(0.04, -0.05);
  s.qd_radps = Vec2(0.5, -0.8);
  arm.set_joint_state(s);
  const auto energy = [&] {
    const Vec2 dq = arm.joint_state().q_rad - q_d;
    return arm.kinetic_energy_j() + 0.5 * dq.dot(kq * dq);
  };
  const double e0 = energy();
  double worst = 0.0, worst_last_second = 0.0, min_tension = 1e9;
  const double step = p.step_s;
  const auto n = static_cast<long>(std::lround(10.0 / step));
  for (long k = 0; k < n; ++k) {
    Mat2 m_x;
    Vec2 h;
    arm.endpoint_dynamics_for_step(step, m_x, h);
    arm.advance(step, m_x.inverse() * h);
    const double rel = std::abs(energy() - e0) / e0;
    worst = std::max(worst, rel);
    if (k > n - static_cast<long>(1.0 / step)) worst_last_second = std::max(worst_last_second, rel);
    if (k % 64 == 0) min_tension = std::min(min_tension, arm.tensions_n().minCoeff());
  }
  INFO("springs: max relative energy error " << worst << ", in the last second " << worst_last_second
                                             << ", min tension " << min_tension << " N");
  REQUIRE(min_tension > 0.0);  // no muscle went slack: the field stayed conservative
  CHECK(worst < 2e-3);
  CHECK(worst_last_second < 2e-3);
}

TEST_CASE("neuromech: inverse then forward dynamics reproduces the minimum-jerk plan") {
  // Feed-forward only (no feedback, no noise) on the ideal admittance the
  // feed-forward expects, the plant stepping at the model's rate. Open loop (no
  // muscle impedance) the only error is the integrator's: it halves with the step.
  // With the intrinsic impedance the same error is pulled back towards the plan.
  // Measured at 4 kHz (trapezoidal position update, feed-forward held per step):
  // see the INFO line; the bound is 1.2e-4 m for the 0.8 s reach.
  const auto max_error = [](bool intrinsic, double duration_s, double rate_hz) {
    NeuromechParams p = quiet(NeuromechParams{});
    p.disable_feedback();
    p.step_s = 1.0 / rate_hz;
    if (!intrinsic) {
      p.k0_npm.setZero();
      p.k1_per_m.setZero();
    }
    NeuromechanicalArm arm(p);
    ReachSpec r;
    r.duration_s = duration_s;
    r.lateral_bow_m = 0.01;
    const Trial t = run_trial(arm, r, 7, 0.0, 0.0, rate_hz);
    double worst = 0.0;
    for (std::size_t k = 0; k < t.x.size(); ++k) {
      const auto s = min_jerk(r.start_shoulder_m, r.goal_shoulder_m, r.t_start_s, r.duration_s, r.lateral_bow_m,
                              static_cast<double>(k) / rate_hz);
      worst = std::max(worst, (t.x[k] - s.x).norm());
    }
    return std::max(worst, (t.x.back() - r.goal_shoulder_m).norm());
  };
  // The feed-forward is held over each step (a neural command): first order.
  for (const double duration : {3.0, 0.8}) {
    const double e4 = max_error(false, duration, 4000.0);
    const double e8 = max_error(false, duration, 8000.0);
    const double e4_intrinsic = max_error(true, duration, 4000.0);
    INFO(duration << " s reach: max |x - x_plan| open loop " << e4 << " m at 4 kHz, " << e8
                  << " m at 8 kHz; with the intrinsic impedance " << e4_intrinsic << " m at 4 kHz");
    CHECK(e4 < 1.2e-4);
    CHECK(e8 < 0.6 * e4);
    CHECK(e4_intrinsic < e4);
  }
}

TEST_CASE("neuromech: a zero-amplitude perturbation gives identical paired runs - runs are deterministic per seed") {
  NeuromechanicalArm arm(NeuromechParams{});  // the paper's configuration, with noise
  ReachSpec r;
  r.lateral_bow_m = 0.004;
  const Trial twin = run_trial(arm, r, 42, 0.0, 30 * kDeg);
  const Trial zero = run_trial(arm, r, 42, 0.0 * 15.0, 30 * kDeg);
  const Trial again = run_trial(arm, r, 42, 0.0, 30 * kDeg);
  const Trial other = run_trial(arm, r, 43, 0.0, 30 * kDeg);
  REQUIRE(twin.x.size() == zero.x.size());
  bool same_zero = true, same_again = true;
  double diff_other = 0.0;
  for (std::size_t k = 0; k < twin.x.size(); ++k) {
    same_zero = same_zero && twin.x[k] == zero.x[k];
    same_again = same_again && twin.x[k] == again.x[k];
    diff_other = std::max(diff_other, (twin.x[k] - other.x[k]).norm());
  }
  CHECK(same_zero);
  CHECK(same_again);
  CHECK(diff_other > 1e-5);  // another seed is another noise realisation

  // A real perturbation leaves the run identical up to the onset.
  const Trial pert = run_trial(arm, r, 42, 15.0, 30 * kDeg);
  REQUIRE(pert.onset == twin.onset);
  bool same_before = true;
  for (long k = 0; k <= pert.onset; ++k) same_before = same_before && pert.x[static_cast<std::size_t>(k)] == twin.x[static_cast<std::size_t>(k)];
  CHECK(same_before);
  CHECK(pert.x[static_cast<std::size_t>(pert.onset + 200)] != twin.x[static_cast<std::size_t>(pert.onset + 200)]);
}

TEST_CASE("neuromech: begin_trial, endpoint_dynamics, advance and the truth functions never allocate") {
  NeuromechParams p;
  p.step_s = p.session_step_s;                   // 4 kHz model: 0.25 ms plant steps, and 16 kHz sub-steps below
  for (auto& f : p.feedback) f.enabled = true;  // largest delay line in use
  NeuromechanicalArm arm(p);
  const PlantParams plant = test_plant();
  PerturbationProfile prof;
  ReachSpec r;
  r.lateral_bow_m = 0.005;
  Mat2 d, k;
  manip::test::GlobalAllocScope allocs;
  for (std::uint64_t trial = 0; trial < 3; ++trial) {
    arm.begin_trial(r, trial);
    for (int n = 0; n < 8000; ++n) {
      plant_step(arm, plant, prof.force_n((n - 6000) / 4000.0, 1.0), 0.25e-3);
      arm.endpoint_impedance(d, k);
      arm.endpoint_impedance_eq16_18(d, k);
      arm.reflex_endpoint_gains(Pathway::kShortLatency, d, k);
    }
    for (int n = 0; n < 400; ++n) plant_step(arm, plant, Vec2::Zero(), 0.0625e-3);  // sub-stepped (manip_rt's 16 kHz)
  }
  CHECK(allocs.news() == 0);
  // The counter works: a std::vector allocates.
  const long after = allocs.news();
  std::vector<int> v(3);
  CHECK(allocs.news() > after);
}

TEST_CASE("neuromech: endpoint_impedance is the linearisation of the endpoint dynamics (finite differences)") {
  const auto check_state = [](const NeuromechanicalArm& arm, const char* what) {
    Mat2 d, k, d_fd, k_fd, d_s, k_s;
    arm.endpoint_impedance(d, k);
    arm.endpoint_impedance_eq16_18(d_s, k_s);
    fd_impedance(arm, d_fd, k_fd);
    INFO(what << "\nK full\n" << k << "\nK fd\n" << k_fd << "\nK eq.18\n" << k_s << "\nD full\n" << d << "\nD fd\n" << d_fd
              << "\nD eq.17\n" << d_s);
    // No muscle at the kink of the tension clamp (taut by > 1 N, or slack).
    const MuscleVec t = arm.tensions_n();
    REQUIRE(((t.array() > 1.0) || (t.array() == 0.0)).all());
    CHECK((k - k_fd).norm() < 1e-5 * k.norm());
    CHECK((d - d_fd).norm() < 1e-5 * d.norm());
    return std::pair{(k - k_s).norm(), (d - d_s).norm()};
  };

  // (a) Mid-reach, 80 ms into a 15 N perturbation, reflexes and noise on: off the plan.
  NeuromechParams p;
  for (auto& f : p.feedback) f.enabled = true;
  NeuromechanicalArm arm(p);
  const PlantParams plant = test_plant();
  PerturbationProfile prof;
  ReachSpec r;
  arm.begin_trial(r, 3);
  long onset = -1;
  for (long n = 0;; ++n) {
    if (onset < 0 && arm.hand_position_m().y() >= 0.40) onset = n;
    if (onset >= 0 && n - onset == 320) break;
    plant_step(arm, plant, onset >= 0 ? prof.force_n((n - onset) / 4000.0, 60 * kDeg) : Vec2::Zero(), 0.25e-3);
  }
  const auto [dk_a, dd_a] = check_state(arm, "perturbed reach");
  CHECK(dk_a > 1e-3);  // the geometric terms are resolved by the test

  // (b) A brisk artificial state with a large imposed acceleration: the terms the
  // paper drops (dC/dq, dM/dq qdd, d(J^T)/dq u, the kinematic chain) are large.
  JointState s;
  s.q_rad = Vec2(0.6, 1.4);
  s.qd_radps = Vec2(1.2, -1.8);
  arm.set_joint_state(s);
  arm.advance(arm.params().step_s, Vec2(4.0, -3.0));
  const auto [dk_b, dd_b] = check_state(arm, "brisk state");
  CHECK(dk_b > 10.0);
  CHECK(dd_b > 1.0);
}

TEST_CASE("neuromech: intrinsic endpoint impedance at mid-reach lies in the literature ranges") {
  // Intrinsic only (all pathways off), unperturbed, x = (0, 0.40) m on the way out.
  // Ranges during movement: stiffness ~100-400 N/m, damping ~5-20 N s/m.
  NeuromechParams p = quiet(NeuromechParams{});
  p.disable_feedback();
  NeuromechanicalArm arm(p);
  const PlantParams plant = test_plant();
  arm.begin_trial(ReachSpec{}, 1);
  while (arm.hand_position_m().y() < 0.40) plant_step(arm, plant, Vec2::Zero(), 0.25e-3);
  Mat2 d, k, d_s, k_s;
  arm.endpoint_impedance(d, k);
  arm.endpoint_impedance_eq16_18(d_s, k_s);
  INFO("K\n" << k << "\nD\n" << d << "\nK eq.18\n" << k_s << "\nD eq.17\n" << d_s);
  // The diagonal elements (the stiffness/damping along each axis, as the
  // literature reports them) in range; positive definite.
  for (const Mat2& kk : {k, k_s}) {
    CHECK(kk(0, 0) >= 100.0);
    CHECK(kk(0, 0) <= 400.0);
    CHECK(kk(1, 1) >= 100.0);
    CHECK(kk(1, 1) <= 400.0);
    CHECK(sym_eig(kk)(0) > 0.0);
  }
  for (const Mat2& dd : {d, d_s}) {
    CHECK(dd(0, 0) >= 5.0);
    CHECK(dd(0, 0) <= 20.0);
    CHECK(dd(1, 1) >= 5.0);
    CHECK(dd(1, 1) <= 20.0);
    CHECK(sym_eig(dd)(0) > 0.0);
  }
  // The stiffness is nearly symmetric (intrinsic, spring-like; paper §3.3).
  CHECK(std::abs(k(0, 1) - k(1, 0)) < 0.1 * k.norm());
}

TEST_CASE("neuromech: a 15 N pulse deviates the hand by millimetres and every feedback configuration settles") {
  struct Config {
    const char* name;
    bool s, l, v;
  };
  for (const Config c : {Config{"intrinsic", false, false, false}, Config{"paper 60 ms", false, true, false},
                         Config{"short-latency", true, false, false}, Config{"all pathways", true, true, true}}) {
    NeuromechParams p = quiet(NeuromechParams{});
    p.pathway(Pathway::kShortLatency).enabled = c.s;
    p.pathway(Pathway::kLongLatency).enabled = c.l;
    p.pathway(Pathway::kVoluntary).enabled = c.v;
    NeuromechanicalArm arm(p);
    ReachSpec r;
    for (const double angle : {30.0, 240.0}) {  // one angle per quadrant pair (the response is odd in u_pert)
      const Trial twin = run_trial(arm, r, 5, 0.0, angle * kDeg, 4000.0, 1.0);
      const Trial pert = run_trial(arm, r, 5, 15.0, angle * kDeg, 4000.0, 1.0);
      const Vec2 dev = max_deviation(pert, twin);
      INFO(c.name << " angle " << angle << ": max deviation " << dev.transpose() * 1e3 << " mm");
      CHECK(dev.maxCoeff() > 1e-3);
      CHECK(dev.maxCoeff() < 15e-3);
      // The response (perturbed - twin) dies out: its size over the last 0.5 s of
      // the trial (~2.2-2.7 s after onset) is a small fraction of its peak.
      double peak = 0.0, late = 0.0;
      for (std::size_t k = static_cast<std::size_t>(pert.onset); k < pert.x.size(); ++k) {
        const double d = (pert.x[k] - twin.x[k]).norm();
        peak = std::max(peak, d);
        if (k + 2000 >= pert.x.size()) late = std::max(late, d);
      }
      INFO("response peak " << peak * 1e3 << " mm, over the last 0.5 s " << late * 1e3 << " mm");
      CHECK(late < 0.05 * peak);
      CHECK((pert.x.back() - r.goal_shoulder_m).norm() < 2e-3);
    }
  }
}

TEST_CASE("neuromech: a delayed pathway changes nothing before its delay has elapsed") {
  // Perturbed minus twin with and without the 60 ms long-latency pathway: equal
  // (up to the pathway's response to the twin's own tiny tracking error) until the
  // delay has elapsed, different afterwards.
  ReachSpec r;
  NeuromechParams pi = quiet(NeuromechParams{});
  pi.disable_feedback();
  NeuromechParams pl = pi;
  pl.pathway(Pathway::kLongLatency).enabled = true;
  NeuromechanicalArm a_i(pi), a_l(pl);
  const long onset = 7356;  // where x2 crosses 0.40 m
  const Trial ti = run_trial(a_i, r, 1, 0.0, 60 * kDeg, 4000.0, 0.5, onset);
  const Trial pi_ = run_trial(a_i, r, 1, 15.0, 60 * kDeg, 4000.0, 0.5, onset);
  const Trial tl = run_trial(a_l, r, 1, 0.0, 60 * kDeg, 4000.0, 0.5, onset);
  const Trial pl_ = run_trial(a_l, r, 1, 15.0, 60 * kDeg, 4000.0, 0.5, onset);
  REQUIRE(pi_.onset == onset);
  const auto dev = [](const Trial& p, const Trial& t, long k) {
    return Vec2(p.x[static_cast<std::size_t>(k)] - t.x[static_cast<std::size_t>(k)]);
  };
  double before = 0.0, after = 0.0;
  for (long k = pi_.onset; k < pi_.onset + 600; ++k) {
    const double d = (dev(pi_, ti, k) - dev(pl_, tl, k)).norm();
    if (k <= pi_.onset + 240) before = std::max(before, d);  // 60 ms at 4 kHz (+1 sample of response)
    else after = std::max(after, d);
  }
  INFO("difference before the delay " << before << " m, after " << after << " m");
  CHECK(before < 1e-9);
  CHECK(after > 1e-5);
}

TEST_CASE("neuromech: advance rejects a step that is neither a whole multiple nor a whole fraction of the model step") {
  NeuromechanicalArm arm(NeuromechParams{});
  CHECK_THROWS_AS(arm.advance(1.5 * arm.params().step_s, Vec2::Zero()), std::invalid_argument);
  CHECK_NOTHROW(arm.advance(4 * arm.params().step_s, Vec2::Zero()));
  CHECK(arm.time_s() == Approx(4 * arm.params().step_s));
  // A whole fraction of the step: the plant sub-steps the model (manip_rt's sim substeps).
  CHECK_NOTHROW(arm.advance(arm.params().step_s / 4, Vec2::Zero()));
  CHECK(arm.time_s() == Approx(4.25 * arm.params().step_s));
  CHECK_THROWS_AS(arm.advance(arm.params().step_s / 3, Vec2::Zero()), std::invalid_argument);  // mid-step change
  CHECK_THROWS_AS(arm.advance(arm.params().step_s / 2.5, Vec2::Zero()), std::invalid_argument);
  ReachSpec far;
  far.goal_shoulder_m = Vec2(0.0, 0.9);
  CHECK_THROWS_AS(arm.begin_trial(far, 1), std::invalid_argument);
}

TEST_CASE("neuromech: a small pulse on the arm at rest follows the exact solution of its linearisation") {
  // Independent reference: at rest with a plan that stays put (intrinsic, no noise)
  // the arm is in equilibrium; for a pulse small enough that the nonlinearity is
  // negligible (0.015 N: ~20 um) the hand follows the linear system
  //   (M_x + M_adm + M_handle) dxdd + (D + D_adm) dxd + K dx = u_pert
  // with M_x from endpoint_dynamics and D, K from endpoint_impedance (the analytic
  // linearisation), solved exactly for the force held per 4 kHz cycle (matrix
  // exponential). The midpoint plant step is second order; the explicit one
  // (forces from the start of the step) first order.
  NeuromechParams p = quiet(NeuromechParams{});
  p.disable_feedback();
  const PlantParams plant = test_plant();
  PerturbationProfile prof;
  prof.amplitude_n = 0.015;
  ReachSpec still;
  still.goal_shoulder_m = still.start_shoulder_m;
  const double angle = 60 * kDeg, fs = 4000.0;
  const int n = 1200;  // 300 ms: the pulse and the response after it
  const auto simulate = [&](double step_s, bool midpoint) {
    NeuromechParams q = p;
    q.step_s = step_s;
    NeuromechanicalArm arm(q);
    arm.begin_trial(still, 1);
    const Vec2 x0 = arm.hand_position_m();
    std::vector<Vec2> dx;
    for (int k = 0; k < n; ++k) {
      dx.push_back(arm.hand_position_m() - x0);
      const Vec2 u = prof.force_n(k / fs, angle);
      if (step_s < 1.0 / fs) {
        const int m = static_cast<int>(std::lround(1.0 / (fs * step_s)));
        for (int j = 0; j < m; ++j) plant_step(arm, plant, u, step_s, midpoint);
      } else {
        plant_step(arm, plant, u, 1.0 / fs, midpoint);
      }
    }
    return dx;
  };
  NeuromechanicalArm arm(p);
  arm.begin_trial(still, 1);
  Mat2 m_x, d, k;
  Vec2 h;
  arm.endpoint_dynamics(m_x, h);
  arm.endpoint_impedance(d, k);
  REQUIRE(h.norm() < 1e-9);  // an equilibrium
  const Mat2 minv = (m_x + plant.m_adm_kg + plant.m_handle_kg).inverse();
  Eigen::Matrix<double, 6, 6> aug = Eigen::Matrix<double, 6, 6>::Zero();
  aug.block<2, 2>(0, 2) = Mat2::Identity();
  aug.block<2, 2>(2, 0) = -minv * k;
  aug.block<2, 2>(2, 2) = -minv * (d + plant.d_adm_nspm);
  aug.block<2, 2>(2, 4) = minv;
  const Eigen::Matrix<double, 6, 6> e = (aug / fs).exp();
  std::vector<Vec2> ref;
  Eigen::Vector4d z = Eigen::Vector4d::Zero();
  double peak = 0.0;
  for (int i = 0; i < n; ++i) {
    ref.push_back(z.head<2>());
    peak = std::max(peak, z.head<2>().norm());
    z = e.block<4, 4>(0, 0) * z + e.block<4, 2>(0, 4) * prof.force_n(i / fs, angle);
  }
  const auto rel_error = [&](const std::vector<Vec2>& dx) {
    double worst = 0.0;
    for (int i = 0; i < n; ++i) worst = std::max(worst, (dx[static_cast<std::size_t>(i)] - ref[static_cast<std::size_t>(i)]).norm());
    return worst / peak;
  };
  const double mid4 = rel_error(simulate(1.0 / 4000.0, true));
  const double mid8 = rel_error(simulate(1.0 / 8000.0, true));
  const double exp4 = rel_error(simulate(1.0 / 4000.0, false));
  const double exp8 = rel_error(simulate(1.0 / 8000.0, false));
  INFO("peak " << peak * 1e6 << " um; max error / peak: midpoint 4 kHz " << mid4 << ", 8 kHz " << mid8
               << "; explicit 4 kHz " << exp4 << ", 8 kHz " << exp8);
  CHECK(peak > 10e-6);
  CHECK(mid4 < 1e-4);
  CHECK(mid4 < 0.25 * exp4);
}
