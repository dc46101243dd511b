// NeuromechanicalArm: dynamics, integration and ground-truth linearisation.
// The model and the integration scheme are described in the header.
#include "manip/sim/neuromech_arm.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "manip/sim/min_jerk.hpp"

namespace manip::sim {
namespace {

Mat2 inverse2(const Mat2& m) {
  const double det = m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0);
  Mat2 r;
  r << m(1, 1), -m(0, 1), -m(1, 0), m(0, 0);
  return r / det;
}

}  // namespace

// ---- NeuromechanicalArm -----------------------------------------------------

NeuromechanicalArm::NeuromechanicalArm(const NeuromechParams& p) : p_(p), arm_(p.anthropometrics) {
  if (auto why = p_.invalid_reason()) throw std::invalid_argument("neuromech params: " + *why);
  int max_delay = 0;
  for (int i = 0; i < kPathways; ++i) {
    const auto& f = p_.feedback[static_cast<std::size_t>(i)];
    delay_steps_[static_cast<std::size_t>(i)] = static_cast<int>(std::lround(f.delay_s / p_.step_s));
    if (f.enabled) max_delay = std::max(max_delay, delay_steps_[static_cast<std::size_t>(i)]);
  }
  // Slots for steps n - max_delay .. n: a pathway reads the error max_delay steps back.
  ring_len_ = max_delay + 1;
  ring_.assign(static_cast<std::size_t>(4 * ring_len_), 0.0);
  // Exact Ornstein-Uhlenbeck update over one step (unit stationary variance).
  noise_rho_ = std::exp(-p_.step_s / p_.noise_tau_s);
  noise_sigma_ = std::sqrt(1.0 - noise_rho_ * noise_rho_);
  const auto& an = p_.anthropometrics;
  const double l1 = an.length_m[0], r1 = an.com_m[0], r2 = an.com_m[1];
  m_d_ = an.inertia_kgm2[1] + an.mass_kg[1] * r2 * r2;
  m_a_ = an.inertia_kgm2[0] + an.mass_kg[0] * r1 * r1 + an.mass_kg[1] * l1 * l1 + m_d_;
  m_b_ = an.mass_kg[1] * l1 * r2;
  aat_inv_ = inverse2(p_.moment_arms_m * p_.moment_arms_m.transpose());
  a_tonic_torque_ = p_.moment_arms_m * p_.tonic_activation_n;
  begin_trial(ReachSpec{}, 0);
}

// Same formulas as TwoLinkArm (a test checks them against it), with the sines and
// cosines computed once per posture: they dominated the cost of a step.
NeuromechanicalArm::Posture NeuromechanicalArm::posture(const Vec2& q) const {
  // Locals, so that the compiler fuses each sin/cos pair into one sincos call.
  const double a1 = q(0), a2 = q(1);
  const double s1 = std::sin(a1), c1 = std::cos(a1);
  const double s2 = std::sin(a2), c2 = std::cos(a2);
  Posture k;
  k.s1 = s1;
  k.c1 = c1;
  k.s2 = s2;
  k.c2 = c2;
  k.s12 = s1 * c2 + c1 * s2;
  k.c12 = c1 * c2 - s1 * s2;
  return finish_posture(k);
}

NeuromechanicalArm::Posture NeuromechanicalArm::finish_posture(Posture k) const {
  const double l1 = p_.anthropometrics.length_m[0], l2 = p_.anthropometrics.length_m[1];
  k.x << l1 * k.c1 + l2 * k.c12, l1 * k.s1 + l2 * k.s12;
  k.j << -l1 * k.s1 - l2 * k.s12, -l2 * k.s12, l1 * k.c1 + l2 * k.c12, l2 * k.c12;
  k.jinv = inverse2(k.j);
  const double off = m_d_ + m_b_ * k.c2;
  k.mq << m_a_ + 2.0 * m_b_ * k.c2, off, off, m_d_;  // eq. 1
  return k;
}

bool NeuromechanicalArm::posture_at_hand(const Vec2& x, Vec2& q, Posture& k) const {
  const double l1 = p_.anthropometrics.length_m[0], l2 = p_.anthropometrics.length_m[1];
  const double r2 = x.squaredNorm();
  const double c2 = (r2 - l1 * l1 - l2 * l2) / (2.0 * l1 * l2);
  if (!(c2 > -1.0 && c2 < 1.0)) return false;
  const double s2 = std::sqrt(1.0 - c2 * c2);  // q2 in (0, pi): elbow to the right
  // q1 = atan2(x2, x1) - atan2(l2 s2, l1 + l2 c2); the second angle's cosine and
  // sine are (l1 + l2 c2) / |x| and l2 s2 / |x|, so cos q1 and sin q1 are products.
  const double u = l1 + l2 * c2, v = l2 * s2;
  k.c1 = (x(0) * u + x(1) * v) / r2;
  k.s1 = (x(1) * u - x(0) * v) / r2;
  k.c2 = c2;
  k.s2 = s2;
  k.s12 = k.s1 * c2 + k.c1 * s2;
  k.c12 = k.c1 * c2 - k.s1 * s2;
  q << std::atan2(k.s1, k.c1), std::atan2(s2, c2);
  k = finish_posture(k);
  return true;
}

Mat2 NeuromechanicalArm::jacobian_dot(const Posture& k, const Vec2& qd) const {
  const double l1 = p_.anthropometrics.length_m[0], l2 = p_.anthropometrics.length_m[1];
  const double w1 = qd(0), w12 = qd(0) + qd(1);
  Mat2 jd;
  jd << -l1 * k.c1 * w1 - l2 * k.c12 * w12, -l2 * k.c12 * w12, -l1 * k.s1 * w1 - l2 * k.s12 * w12, -l2 * k.s12 * w12;
  return jd;
}

Vec2 NeuromechanicalArm::coriolis(const Posture& k, const Vec2& qd) const {
  const double h = m_b_ * k.s2;
  return Vec2(-h * (2.0 * qd(0) * qd(1) + qd(1) * qd(1)), h * qd(0) * qd(0));
}

void NeuromechanicalArm::set_q(const Vec2& q) {
  js_.q_rad = q;
  pose_ = posture(q);
}

void NeuromechanicalArm::begin_trial(const ReachSpec& reach, std::uint64_t seed) {
  if (!(reach.duration_s > 0.0) || !std::isfinite(reach.t_start_s))
    throw std::invalid_argument("NeuromechanicalArm::begin_trial: reach duration must be positive");
  const auto q0 = arm_.inverse_kinematics(reach.start_shoulder_m);
  if (!q0 || !arm_.inverse_kinematics(reach.goal_shoulder_m))
    throw std::invalid_argument("NeuromechanicalArm::begin_trial: start or goal out of the arm's reach");
  reach_ = reach;
  step_ = 0;
  sub_ = 0;
  lambda_.setZero();
  xdd_last_.setZero();
  rng_.seed(seed);
  // Start the noise in its stationary distribution, so that trials are alike from t = 0.
  for (int i = 0; i < kMuscles; ++i) noise_(i) = rng_.normal();
  set_q(*q0);
  js_.qd_radps.setZero();
  update_plan();
  fill_delay_line();
}

void NeuromechanicalArm::set_joint_state(const JointState& s) {
  set_q(s.q_rad);
  js_.qd_radps = s.qd_radps;
  fill_delay_line();
}

Vec2 NeuromechanicalArm::hand_position_m() const { return pose_.x; }

Vec2 NeuromechanicalArm::hand_velocity_mps() const { return pose_.j * js_.qd_radps; }

// Minimum deviation from the tonic co-contraction that produces tau with pulling
// muscles:  min 1/2 |a - c|^2  s.t.  A a = tau, a >= 0.  KKT: a = max(0, c + A^T lambda).
// lambda minimises the convex, C^1 dual phi(l) = 1/2 |max(0, c + A^T l)|^2 - tau^T l
// (bounded below because the moment arms span every torque direction, checked in
// invalid_reason). Semismooth Newton with backtracking; warm-started from the
// previous step it converges in one or two iterations. Fixed-size: no allocation.
MuscleVec NeuromechanicalArm::distribute(const Vec2& tau_nm) {
  const auto& A = p_.moment_arms_m;
  const MuscleVec& c = p_.tonic_activation_n;
  {
    // Usual case (tonic co-contraction): every muscle active, a = c + A^T lambda with
    // A A^T lambda = tau - A c. It is the exact optimum when all of a is positive.
    const Vec2 lam = aat_inv_ * (tau_nm - a_tonic_torque_);
    const MuscleVec a = c + A.transpose() * lam;
    if (a.minCoeff() > 0.0) {
      lambda_ = lam;
      return a;
    }
  }
  const auto phi = [&](const Vec2& l, MuscleVec& a) {
    a = (c + A.transpose() * l).cwiseMax(0.0);
    return 0.5 * a.squaredNorm() - tau_nm.dot(l);
  };
  const double tol = 1e-11 * (1.0 + tau_nm.norm());
  const double reg = 1e-12 * (A * A.transpose()).trace();
  Vec2 lam = lambda_;
  MuscleVec a;
  double f = phi(lam, a);
  for (int it = 0; it < 60; ++it) {
    const Vec2 g = A * a - tau_nm;
    if (g.norm() <= tol) break;
    Mat2 hess = reg * Mat2::Identity();
    for (int i = 0; i < kMuscles; ++i)
      if (a(i) > 0.0) hess += A.col(i) * A.col(i).transpose();
    const Vec2 dir = -inverse2(hess) * g;
    double step = 1.0;
    MuscleVec a_try;
    double f_try = phi(lam + dir, a_try);
    for (int ls = 0; ls < 40 && f_try > f + 1e-4 * step * g.dot(dir); ++ls) {
      step *= 0.5;
      f_try = phi(lam + step * dir, a_try);
    }
    lam += step * dir;
    a = a_try;
    f = f_try;
  }
  lambda_ = lam;
  return a;
}

void NeuromechanicalArm::update_plan() {
  const auto s = min_jerk(reach_.start_shoulder_m, reach_.goal_shoulder_m, reach_.t_start_s, reach_.duration_s,
                          reach_.lateral_bow_m, time_s());
  plan_.x = s.x;
  plan_.xd = s.xd;
  plan_.xdd = s.xdd;
  Vec2 q;
  Posture k;
  // A plan leaving the workspace (a huge bow) keeps the last reachable posture.
  if (posture_at_hand(s.x, q, k))
    plan_.q = q;
  else
    k = posture(plan_.q);
  plan_.qd = k.jinv * s.xd;
  const Vec2 qdd = k.jinv * (s.xdd - jacobian_dot(k, plan_.qd) * plan_.qd);
  plan_.qdd = qdd;
  Vec2 tau = Vec2::Zero();
  if (p_.feedforward_enabled) {
    // Inverse dynamics of the plan (eq. 1) with the expected external force on
    // the hand, -(M_load xdd + D_load xd): the admittance the person has learnt.
    const Vec2 f_load = p_.load_mass_kg.cwiseProduct(s.xdd) + p_.load_damping_nspm.cwiseProduct(s.xd);
    tau = k.mq * qdd + coriolis(k, plan_.qd) + k.j.transpose() * f_load;
  }
  plan_.a_ff = distribute(tau);
}

void NeuromechanicalArm::push_error() {
  const auto slot = static_cast<std::size_t>(4 * (step_ % ring_len_));
  const Vec2 dq = js_.q_rad - plan_.q, dqd = js_.qd_radps - plan_.qd;
  ring_[slot] = dq(0);
  ring_[slot + 1] = dq(1);
  ring_[slot + 2] = dqd(0);
  ring_[slot + 3] = dqd(1);
}

void NeuromechanicalArm::fill_delay_line() {
  const Vec2 dq = js_.q_rad - plan_.q, dqd = js_.qd_radps - plan_.qd;
  for (int k = 0; k < ring_len_; ++k) {
    const auto slot = static_cast<std::size_t>(4 * k);
    ring_[slot] = dq(0);
    ring_[slot + 1] = dq(1);
    ring_[slot + 2] = dqd(0);
    ring_[slot + 3] = dqd(1);
  }
}

// Feed-forward plus every enabled pathway's PD response to the muscle-level
// tracking error one delay ago (eq. 4). Homonymous: a muscle responds to its own
// stretch e_m = -A^T (q - q_d) and stretch rate.
MuscleVec NeuromechanicalArm::feedback_drive() const {
  MuscleVec u = plan_.a_ff;
  const auto& A = p_.moment_arms_m;
  for (int i = 0; i < kPathways; ++i) {
    const auto& f = p_.feedback[static_cast<std::size_t>(i)];
    if (!f.enabled) continue;
    // Steps before the trial started hold the initial error (filled in begin_trial).
    const std::int64_t k = ((step_ - delay_steps_[static_cast<std::size_t>(i)]) % ring_len_ + ring_len_) % ring_len_;
    const auto slot = static_cast<std::size_t>(4 * k);
    const Vec2 dq(ring_[slot], ring_[slot + 1]), dqd(ring_[slot + 2], ring_[slot + 3]);
    u.noalias() -= A.transpose() * (f.kp_npm * dq + f.kd_nspm * dqd);
  }
  return u;
}

NeuromechanicalArm::Muscles NeuromechanicalArm::muscles_at(const Vec2& q, const Vec2& qd) const {
  const auto& A = p_.moment_arms_m;
  Muscles m;
  const MuscleVec u = feedback_drive();
  // Signal-dependent noise (eq. 3 a_N): std proportional to the non-negative command.
  const MuscleVec amp = (p_.noise_floor_n + p_.noise_cv * u.cwiseMax(0.0).array()).matrix();
  const MuscleVec a_raw = u + amp.cwiseProduct(noise_);
  m.a = a_raw.cwiseMax(0.0);  // muscles pull: a >= 0
  m.k = p_.k0_npm + p_.k1_per_m.cwiseProduct(m.a);  // eq. 35
  m.d = m.k / p_.stiffness_to_damping_per_s;        // eq. 35
  const MuscleVec e = -A.transpose() * (q - plan_.q);
  const MuscleVec ed = -A.transpose() * (qd - plan_.qd);
  const MuscleVec pre = m.a + m.d.cwiseProduct(ed) + m.k.cwiseProduct(e);  // eq. 33-34
  m.tension = pre.cwiseMax(0.0);
  for (int i = 0; i < kMuscles; ++i) {
    m.active(i) = pre(i) > 0.0 ? 1.0 : 0.0;
    const double da_du = a_raw(i) > 0.0 ? 1.0 + (u(i) > 0.0 ? p_.noise_cv * noise_(i) : 0.0) : 0.0;
    const double dm_da = 1.0 + p_.k1_per_m(i) * (e(i) + ed(i) / p_.stiffness_to_damping_per_s);
    m.dtension_du(i) = m.active(i) * dm_da * da_du;
  }
  return m;
}

MuscleVec NeuromechanicalArm::activations_n() const { return muscles_at(js_.q_rad, js_.qd_radps).a; }

MuscleVec NeuromechanicalArm::tensions_n() const { return muscles_at(js_.q_rad, js_.qd_radps).tension; }

void NeuromechanicalArm::dynamics_at(const Posture& k, const Vec2& q, const Vec2& qd, Mat2& m_x, Vec2& h) const {
  const Vec2 tau = p_.moment_arms_m * muscles_at(q, qd).tension;  // eq. 2
  m_x = k.jinv.transpose() * k.mq * k.jinv;                         // eq. 16
  // M_q qdd + C = tau + J^T u with qdd = J^-1 (xdd - Jd qd)  =>  M_x xdd = h + u.
  h = k.jinv.transpose() * (tau - coriolis(k, qd)) + m_x * (jacobian_dot(k, qd) * qd);
}

void NeuromechanicalArm::endpoint_dynamics(Mat2& m_x_kg, Vec2& h_n) {
  dynamics_at(pose_, js_.q_rad, js_.qd_radps, m_x_kg, h_n);
}

void NeuromechanicalArm::endpoint_dynamics_for_step(double dt_s, Mat2& m_eff_kg, Vec2& h_eff_n) {
  // As dynamics_at, with the muscles' stiffness and damping forces taken at the middle
  // of the plant's step (linearised about the start): with tau = A m,
  //   tau(t + dt/2) = tau - dt/2 [Kq (qd - qd_d) + Dq (qdd - qdd_d)],  Kq, Dq = A diag(K_m, D_m) A^T
  // (active muscles), qdd = J^-1 (xdd - Jd qd). The xdd term moves to the inertia:
  //   M_eff = M_x + dt/2 J^-T Dq J^-1,  h_eff = h - dt/2 J^-T [Kq (qd - qd_d) - Dq (J^-1 Jd qd + qdd_d)].
  // The neural state (activations, noise, delayed feedback) is held over the step.
  const auto& A = p_.moment_arms_m;
  const Vec2& q = js_.q_rad;
  const Vec2& qd = js_.qd_radps;
  const Muscles m = muscles_at(q, qd);
  const Posture& k = pose_;
  const Vec2 tau = A * m.tension;
  const Mat2 jd = jacobian_dot(k, qd);
  const Mat2 m_x = k.jinv.transpose() * k.mq * k.jinv;
  const Vec2 jdqd = jd * qd;
  const Mat2 kq = A * m.k.cwiseProduct(m.active).asDiagonal() * A.transpose();
  const Mat2 dq = A * m.d.cwiseProduct(m.active).asDiagonal() * A.transpose();
  const double half = 0.5 * dt_s;
  m_eff_kg = m_x + half * (k.jinv.transpose() * dq * k.jinv);
  const Vec2 dtau = kq * (qd - plan_.qd) - dq * (k.jinv * jdqd + plan_.qdd);
  h_eff_n = k.jinv.transpose() * (tau - coriolis(k, qd) - half * dtau) + m_x * jdqd;
}

void NeuromechanicalArm::endpoint_dynamics_at(const Vec2& x, const Vec2& xd, Mat2& m_x_kg, Vec2& h_n) const {
  Vec2 q;
  Posture k;
  if (!posture_at_hand(x, q, k)) throw std::invalid_argument("NeuromechanicalArm::endpoint_dynamics_at: point out of reach");
  dynamics_at(k, q, k.jinv * xd, m_x_kg, h_n);
}

void NeuromechanicalArm::integrate(double h, const Vec2& xdd_hand_mps2) {
  // Joint-space update that is exact for the hand acceleration the plant holds over
  // the step (the plant's force, like the controller's command, is held per step):
  //   qdd = J^-1 (xdd - Jd qd);  qd' = qd + h qdd;  q' = q + h (qd + qd') / 2
  // i.e. q' = q + h qd + h^2/2 qdd. Symplectic Euler (q' = q + h qd') instead moves
  // the position by h^2 qdd in the first step of a constant force: it applies every
  // held force half a step early, and that h/2 lead of the response biased impedance
  // estimates on simulated logs by ~10 % at 4 kHz (docs/simulation.md).
  Vec2& qd = js_.qd_radps;
  const Vec2 qdd = pose_.jinv * (xdd_hand_mps2 - jacobian_dot(pose_, qd) * qd);
  const Vec2 qd0 = qd;
  qd += h * qdd;
  set_q(js_.q_rad + (0.5 * h) * (qd0 + qd));
}

void NeuromechanicalArm::neural_step() {
  ++step_;
  for (int i = 0; i < kMuscles; ++i) noise_(i) = noise_rho_ * noise_(i) + noise_sigma_ * rng_.normal();
  update_plan();
  push_error();
}

void NeuromechanicalArm::advance(double dt_s, const Vec2& xdd_hand_mps2) {
  xdd_last_ = xdd_hand_mps2;
  const double ratio = dt_s / p_.step_s;
  if (ratio >= 1.0 - 1e-9 && sub_ == 0) {
    // The plant's step is a whole number of model steps (the usual case).
    const long n = std::lround(ratio);
    if (n < 1 || std::abs(ratio - static_cast<double>(n)) > 1e-6 * ratio)
      throw std::invalid_argument(
          "NeuromechanicalArm::advance: dt must be a whole multiple or a whole fraction of integration.step_s");
    for (long s = 0; s < n; ++s) {
      integrate(p_.step_s, xdd_hand_mps2);
      neural_step();
    }
    return;
  }
  // The plant sub-steps the model step (e.g. manip_rt's 16 kHz sim substeps with a
  // 4 kHz model step): the mechanics follow every sub-step, the neural state
  // (plan, delay lines, noise) advances once per model step.
  const double inv = p_.step_s / dt_s;
  const long m = std::lround(inv);
  if (m < 2 || std::abs(inv - static_cast<double>(m)) > 1e-6 * inv || (sub_ != 0 && m != sub_n_))
    throw std::invalid_argument(
        "NeuromechanicalArm::advance: dt must be a whole multiple or a whole fraction of integration.step_s");
  sub_n_ = static_cast<int>(m);
  integrate(dt_s, xdd_hand_mps2);
  if (++sub_ == sub_n_) {
    sub_ = 0;
    neural_step();
  }
}

// ---- ground truth -----------------------------------------------------------

void NeuromechanicalArm::endpoint_impedance_eq16_18(Mat2& d_nspm, Mat2& k_npm) const {
  const auto& A = p_.moment_arms_m;
  const Muscles m = muscles_at(js_.q_rad, js_.qd_radps);
  const Mat2& jinv = pose_.jinv;
  // eq. 11 with the intrinsic muscle impedance: K_q = A diag(K_m) A^T, D_q = A diag(D_m) A^T.
  const Mat2 kq = A * m.k.cwiseProduct(m.active).asDiagonal() * A.transpose();
  const Mat2 dq = A * m.d.cwiseProduct(m.active).asDiagonal() * A.transpose();
  k_npm = jinv.transpose() * kq * jinv;  // eq. 18
  d_nspm = jinv.transpose() * dq * jinv;  // eq. 17
}

void NeuromechanicalArm::endpoint_impedance(Mat2& d_nspm, Mat2& k_npm) const {
  const auto& A = p_.moment_arms_m;
  const auto& an = p_.anthropometrics;
  const Vec2& q = js_.q_rad;
  const Vec2& qd = js_.qd_radps;
  const Muscles m = muscles_at(q, qd);
  const Mat2& jinv = pose_.jinv;
  const Mat2 jd = jacobian_dot(pose_, qd);
  const Mat2& mq = pose_.mq;
  const Mat2 m_x = jinv.transpose() * mq * jinv;
  const Vec2 tau = A * m.tension;
  // Operating point: the acceleration the plant imposed last, and the external
  // force that goes with it, u = J^-T (M_q qdd + C - tau) = M_x xdd - h.
  const Vec2 qdd = jinv * (xdd_last_ - jd * qd);
  const Vec2 u = jinv.transpose() * (mq * qdd + coriolis(pose_, qd) - tau);

  // dJ/dq_i, and the products the chain rule needs (columns i = 1, 2).
  Mat2 h1, h2, g;
  for (int i = 0; i < 2; ++i) {
    const Mat2 dj = jacobian_dot(pose_, Vec2::Unit(i));  // dJ/dq_i
    h1.col(i) = dj * qd;
    h2.col(i) = dj * qdd;
    g.col(i) = dj.transpose() * u;  // d(J^T)/dq_i u
  }
  const double l1 = an.length_m[0], l2 = an.length_m[1];
  const double s1 = pose_.s1, c1 = pose_.c1, s12 = pose_.s12, c12 = pose_.c12;
  const double w1 = qd(0), w12 = qd(0) + qd(1);
  // L = d(Jd qd)/dq with Jd qd = -[l1 c1 w1^2 + l2 c12 w12^2, l1 s1 w1^2 + l2 s12 w12^2].
  Mat2 l;
  l << l1 * s1 * w1 * w1 + l2 * s12 * w12 * w12, l2 * s12 * w12 * w12,  //
      -l1 * c1 * w1 * w1 - l2 * c12 * w12 * w12, -l2 * c12 * w12 * w12;
  // C = hc [-(2 w1 w2 + w2^2), w1^2], hc = m2 l1 r2 sin q2 (TwoLinkArm::coriolis).
  const double hc = m_b_ * pose_.s2, hc_q2 = m_b_ * pose_.c2;
  Mat2 dc_dq, dc_dqd, dmqdd_dq;
  dc_dq << 0.0, -hc_q2 * (2.0 * qd(0) * qd(1) + qd(1) * qd(1)), 0.0, hc_q2 * qd(0) * qd(0);
  dc_dqd << -2.0 * hc * qd(1), -2.0 * hc * (qd(0) + qd(1)), 2.0 * hc * qd(0), 0.0;
  // dM_q/dq2 = -m2 l1 r2 sin q2 [[2, 1], [1, 0]]; M_q does not depend on q1.
  dmqdd_dq << 0.0, -hc * (2.0 * qdd(0) + qdd(1)), 0.0, -hc * qdd(0);

  // Joint-space linearisation of eq. 1-2 (eq. 9-12 with every term kept).
  const Mat2 kq = A * m.k.cwiseProduct(m.active).asDiagonal() * A.transpose() + dc_dq + dmqdd_dq;
  const Mat2 dq = A * m.d.cwiseProduct(m.active).asDiagonal() * A.transpose() + dc_dqd;
  // Map to the endpoint through dq = J^-1 dx, dqd = J^-1 (dxd - H1 dq),
  // dqdd = J^-1 (dxdd - (H2 + L) dq - (H1 + Jd) dqd), and d(J^-T) = -J^-T d(J^T) J^-T.
  d_nspm = jinv.transpose() * dq * jinv - m_x * (h1 + jd) * jinv;
  k_npm = jinv.transpose() * (kq - g) * jinv - m_x * (h2 + l) * jinv - d_nspm * h1 * jinv;
}

void NeuromechanicalArm::reflex_endpoint_gains(Pathway p, Mat2& d_nspm, Mat2& k_npm) const {
  const auto& f = p_.pathway(p);
  if (!f.enabled) {
    d_nspm.setZero();
    k_npm.setZero();
    return;
  }
  const auto& A = p_.moment_arms_m;
  const Muscles m = muscles_at(js_.q_rad, js_.qd_radps);
  const Mat2& jinv = pose_.jinv;
  // du = -kp A^T dq(t - delay)  =>  dtau = -kp A diag(dm/du) A^T dq(t - delay).
  const Mat2 s = jinv.transpose() * (A * m.dtension_du.asDiagonal() * A.transpose()) * jinv;
  k_npm = f.kp_npm * s;
  d_nspm = f.kd_nspm * s;
}

std::string NeuromechanicalArm::truth_model() const {
  // Built with append(): GCC 12 warns falsely (-Wrestrict) on chained operator+.
  std::string delayed;
  for (int i = 0; i < kPathways; ++i) {
    const auto& f = p_.feedback[static_cast<std::size_t>(i)];
    if (!f.enabled) continue;
    if (!delayed.empty()) delayed.append(",");
    delayed.append(pathway_name(static_cast<Pathway>(i)));
    delayed.append("@");
    delayed.append(std::to_string(std::lround(f.delay_s * 1000.0)));
    delayed.append("ms");
  }
  std::string s = "neuromechanical/full-linearisation";
  if (delayed.empty()) {
    s.append(" (intrinsic only)");
  } else {
    s.append(" (intrinsic; delayed pathways not in the truth: ");
    s.append(delayed);
    s.append(")");
  }
  return s;
}

}  // namespace manip::sim
