// NeuromechParams: validation, strict YAML loading and emitting.
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "manip/common/errors.hpp"
#include "manip/common/yaml_reader.hpp"
#include "manip/sim/neuromech_arm.hpp"

namespace manip::sim {
namespace {

constexpr const char* kMuscleNames[kMuscles] = {"shoulder_flexor", "shoulder_extensor", "elbow_flexor",
                                                 "elbow_extensor",  "biarticular_flexor", "biarticular_extensor"};
constexpr const char* kSegments[2] = {"upper_arm", "forearm"};
// Longest accepted pathway delay: bounds the delay line (2 s at 16 kHz = 256 kB).
constexpr double kMaxDelayS = 2.0;

std::string fmt(double v) {
  std::ostringstream s;
  s.precision(10);
  s << v;
  return s.str();
}

std::optional<std::string> check_vec(const MuscleVec& v, const std::string& key, bool strictly_positive) {
  for (int i = 0; i < kMuscles; ++i) {
    const bool ok = std::isfinite(v(i)) && (strictly_positive ? v(i) > 0.0 : v(i) >= 0.0);
    if (!ok)
      return key + ": entry " + std::to_string(i) + " (" + kMuscleNames[i] + ") = " + fmt(v(i)) + " must be " +
             (strictly_positive ? "positive" : "non-negative");
  }
  return std::nullopt;
}

template <int N>
Eigen::Matrix<double, N, 1> vec(yaml::Section& s, const std::string& key) {
  const auto v = s.numbers(key, static_cast<std::size_t>(N));
  Eigen::Matrix<double, N, 1> out;
  for (int i = 0; i < N; ++i) out(i) = v[static_cast<std::size_t>(i)];
  return out;
}

}  // namespace

const char* pathway_name(Pathway p) {
  switch (p) {
    case Pathway::kShortLatency: return "short_latency";
    case Pathway::kLongLatency: return "long_latency";
    case Pathway::kVoluntary: return "voluntary";
  }
  return "?";
}

bool NeuromechParams::operator==(const NeuromechParams& o) const {
  const auto& a = anthropometrics;
  const auto& b = o.anthropometrics;
  for (int i = 0; i < 2; ++i)
    if (a.length_m[i] != b.length_m[i] || a.mass_kg[i] != b.mass_kg[i] || a.com_m[i] != b.com_m[i] ||
        a.inertia_kgm2[i] != b.inertia_kgm2[i])
      return false;
  return step_s == o.step_s && session_step_s == o.session_step_s && moment_arms_m == o.moment_arms_m && k0_npm == o.k0_npm && k1_per_m == o.k1_per_m &&
         stiffness_to_damping_per_s == o.stiffness_to_damping_per_s && tonic_activation_n == o.tonic_activation_n &&
         feedforward_enabled == o.feedforward_enabled && load_mass_kg == o.load_mass_kg &&
         load_damping_nspm == o.load_damping_nspm && feedback == o.feedback && noise_cv == o.noise_cv &&
         noise_floor_n == o.noise_floor_n && noise_tau_s == o.noise_tau_s;
}

void NeuromechParams::disable_feedback() {
  for (auto& f : feedback) f.enabled = false;
}

std::optional<std::string> NeuromechParams::invalid_reason() const {
  if (!(std::isfinite(step_s) && step_s > 0.0 && step_s <= 1e-3))
    return "integration.step_s: " + fmt(step_s) + " must be in (0, 0.001] s";
  if (!(std::isfinite(session_step_s) && session_step_s > 0.0 && session_step_s <= 1e-3))
    return "integration.session_step_s: " + fmt(session_step_s) + " must be in (0, 0.001] s";

  if (auto why = anthropometrics.invalid_reason()) {
    // TwoLinkArm reports "<segment>.<field> <reason>".
    const auto sp = why->find(' ');
    return "anthropometrics." + why->substr(0, sp) + ":" + (sp == std::string::npos ? "" : why->substr(sp));
  }
  {
    // det M_q is smallest with the arm straight or folded (cos q2 = +-1):
    // det = d (a - d) - b^2 with d = I2 + m2 r2^2, a - d = I1 + m1 r1^2 + m2 l1^2, b = m2 l1 r2.
    const auto& an = anthropometrics;
    const double d = an.inertia_kgm2[1] + an.mass_kg[1] * an.com_m[1] * an.com_m[1];
    const double amd = an.inertia_kgm2[0] + an.mass_kg[0] * an.com_m[0] * an.com_m[0] +
                       an.mass_kg[1] * an.length_m[0] * an.length_m[0];
    const double b = an.mass_kg[1] * an.length_m[0] * an.com_m[1];
    if (!(d * amd - b * b > 1e-12 * (d + amd) * (d + amd)))
      return "anthropometrics: the joint inertia matrix M_q (eq. 1) is singular for some posture";
  }

  for (int i = 0; i < kMuscles; ++i) {
    if (!moment_arms_m.col(i).allFinite()) return std::string("muscles.moment_arms_m: entry for ") + kMuscleNames[i] + " is not finite";
    if (moment_arms_m.col(i).norm() == 0.0)
      return std::string("muscles.moment_arms_m: ") + kMuscleNames[i] + " has no moment arm at either joint";
  }
  {
    // Non-negative tensions can produce every joint torque iff the moment-arm
    // columns are not all within one half-plane: largest angular gap < pi.
    std::array<double, kMuscles> ang{};
    for (int i = 0; i < kMuscles; ++i)
      ang[static_cast<std::size_t>(i)] = std::atan2(moment_arms_m(1, i), moment_arms_m(0, i));
    std::sort(ang.begin(), ang.end());
    double gap = ang.front() + 2.0 * std::numbers::pi - ang.back();
    for (std::size_t i = 1; i < ang.size(); ++i) gap = std::max(gap, ang[i] - ang[i - 1]);
    if (!(gap < std::numbers::pi - 1e-9))
      return "muscles.moment_arms_m: pulling muscles cannot produce every joint torque (all moment-arm columns lie "
             "in one half-plane)";
  }
  if (auto w = check_vec(k0_npm, "muscles.k0_npm", false)) return w;
  if (auto w = check_vec(k1_per_m, "muscles.k1_per_m", false)) return w;
  if (!(std::isfinite(stiffness_to_damping_per_s) && stiffness_to_damping_per_s > 0.0))
    return "muscles.stiffness_to_damping_per_s: " + fmt(stiffness_to_damping_per_s) + " must be positive";
  if (auto w = check_vec(tonic_activation_n, "muscles.tonic_activation_n", false)) return w;

  for (int i = 0; i < 2; ++i) {
    if (!(std::isfinite(load_mass_kg(i)) && load_mass_kg(i) >= 0.0))
      return "feedforward.load_mass_kg: " + fmt(load_mass_kg(i)) + " must be non-negative";
    if (!(std::isfinite(load_damping_nspm(i)) && load_damping_nspm(i) >= 0.0))
      return "feedforward.load_damping_nspm: " + fmt(load_damping_nspm(i)) + " must be non-negative";
  }

  for (int i = 0; i < kPathways; ++i) {
    const auto& f = feedback[static_cast<std::size_t>(i)];
    const std::string key = std::string("feedback.") + pathway_name(static_cast<Pathway>(i));
    if (!(std::isfinite(f.delay_s) && f.delay_s >= 0.0 && f.delay_s <= kMaxDelayS))
      return key + ".delay_s: " + fmt(f.delay_s) + " must be in [0, " + fmt(kMaxDelayS) + "] s";
    const double steps = f.delay_s / step_s;
    if (std::abs(steps - std::round(steps)) > 1e-6)
      return key + ".delay_s: " + fmt(f.delay_s) + " s is not a whole number of simulation steps (integration.step_s = " +
             fmt(step_s) + " s)";
    const double session_steps = f.delay_s / session_step_s;
    if (std::abs(session_steps - std::round(session_steps)) > 1e-6)
      return key + ".delay_s: " + fmt(f.delay_s) +
             " s is not a whole number of session steps (integration.session_step_s = " + fmt(session_step_s) + " s)";
    if (f.enabled && std::lround(steps) < 1)
      return key + ".delay_s: an enabled pathway needs a delay of at least one simulation step (a response without "
                   "delay is the intrinsic muscle impedance, eq. 34)";
    if (!(std::isfinite(f.kp_npm) && f.kp_npm >= 0.0)) return key + ".kp_npm: " + fmt(f.kp_npm) + " must be non-negative";
    if (!(std::isfinite(f.kd_nspm) && f.kd_nspm >= 0.0))
      return key + ".kd_nspm: " + fmt(f.kd_nspm) + " must be non-negative";
  }

  if (!(std::isfinite(noise_cv) && noise_cv >= 0.0)) return "noise.cv: " + fmt(noise_cv) + " must be non-negative";
  if (!(std::isfinite(noise_floor_n) && noise_floor_n >= 0.0))
    return "noise.floor_n: " + fmt(noise_floor_n) + " must be non-negative";
  if (!(std::isfinite(noise_tau_s) && noise_tau_s > 0.0)) return "noise.tau_s: " + fmt(noise_tau_s) + " must be positive";
  return std::nullopt;
}

NeuromechParams load_neuromech_params(const std::string& yaml_path) {
  // The strict common reader: every key required, unknown and duplicate keys
  // refused, "file:line: key: reason" (manip::ConfigError).
  const YAML::Node root_node = yaml::load_file(yaml_path);
  yaml::Section root(yaml_path, root_node, "");
  NeuromechParams p;

  auto integ = root.sub("integration");
  p.step_s = integ.any_number("step_s");
  p.session_step_s = integ.any_number("session_step_s");
  integ.finish();

  auto an = root.sub("anthropometrics");
  for (int i = 0; i < 2; ++i) {
    auto seg = an.sub(kSegments[i]);
    p.anthropometrics.length_m[i] = seg.any_number("length_m");
    p.anthropometrics.mass_kg[i] = seg.any_number("mass_kg");
    p.anthropometrics.com_m[i] = seg.any_number("com_m");
    p.anthropometrics.inertia_kgm2[i] = seg.any_number("inertia_kgm2");
    seg.finish();
  }
  an.finish();

  auto mu = root.sub("muscles");
  auto arms = mu.sub("moment_arms_m");
  p.moment_arms_m.row(0) = vec<kMuscles>(arms, "shoulder").transpose();
  p.moment_arms_m.row(1) = vec<kMuscles>(arms, "elbow").transpose();
  arms.finish();
  p.k0_npm = vec<kMuscles>(mu, "k0_npm");
  p.k1_per_m = vec<kMuscles>(mu, "k1_per_m");
  p.stiffness_to_damping_per_s = mu.any_number("stiffness_to_damping_per_s");
  p.tonic_activation_n = vec<kMuscles>(mu, "tonic_activation_n");
  mu.finish();

  auto ff = root.sub("feedforward");
  p.feedforward_enabled = ff.boolean("enabled");
  p.load_mass_kg = vec<2>(ff, "load_mass_kg");
  p.load_damping_nspm = vec<2>(ff, "load_damping_nspm");
  ff.finish();

  auto fb = root.sub("feedback");
  for (int i = 0; i < kPathways; ++i) {
    auto n = fb.sub(pathway_name(static_cast<Pathway>(i)));
    auto& f = p.feedback[static_cast<std::size_t>(i)];
    f.enabled = n.boolean("enabled");
    f.delay_s = n.any_number("delay_s");
    f.kp_npm = n.any_number("kp_npm");
    f.kd_nspm = n.any_number("kd_nspm");
    n.finish();
  }
  fb.finish();

  auto no = root.sub("noise");
  p.noise_cv = no.any_number("cv");
  p.noise_floor_n = no.any_number("floor_n");
  p.noise_tau_s = no.any_number("tau_s");
  no.finish();
  root.finish();

  if (auto why = p.invalid_reason()) throw ConfigError(yaml_path + ": " + *why);
  return p;
}

std::string neuromech_params_to_yaml(const NeuromechParams& p) {
  const auto seq = [](const auto& v) {
    YAML::Node n(YAML::NodeType::Sequence);
    for (Eigen::Index i = 0; i < v.size(); ++i) n.push_back(v(i));
    n.SetStyle(YAML::EmitterStyle::Flow);
    return n;
  };
  YAML::Node root;
  root["integration"]["step_s"] = p.step_s;
  root["integration"]["session_step_s"] = p.session_step_s;
  for (int i = 0; i < 2; ++i) {
    YAML::Node s = root["anthropometrics"][kSegments[i]];
    s["length_m"] = p.anthropometrics.length_m[i];
    s["mass_kg"] = p.anthropometrics.mass_kg[i];
    s["com_m"] = p.anthropometrics.com_m[i];
    s["inertia_kgm2"] = p.anthropometrics.inertia_kgm2[i];
  }
  YAML::Node mu = root["muscles"];
  mu["moment_arms_m"]["shoulder"] = seq(MuscleVec(p.moment_arms_m.row(0).transpose()));
  mu["moment_arms_m"]["elbow"] = seq(MuscleVec(p.moment_arms_m.row(1).transpose()));
  mu["k0_npm"] = seq(p.k0_npm);
  mu["k1_per_m"] = seq(p.k1_per_m);
  mu["stiffness_to_damping_per_s"] = p.stiffness_to_damping_per_s;
  mu["tonic_activation_n"] = seq(p.tonic_activation_n);
  root["feedforward"]["enabled"] = p.feedforward_enabled;
  root["feedforward"]["load_mass_kg"] = seq(p.load_mass_kg);
  root["feedforward"]["load_damping_nspm"] = seq(p.load_damping_nspm);
  for (int i = 0; i < kPathways; ++i) {
    const auto& f = p.feedback[static_cast<std::size_t>(i)];
    YAML::Node n = root["feedback"][pathway_name(static_cast<Pathway>(i))];
    n["enabled"] = f.enabled;
    n["delay_s"] = f.delay_s;
    n["kp_npm"] = f.kp_npm;
    n["kd_nspm"] = f.kd_nspm;
  }
  root["noise"]["cv"] = p.noise_cv;
  root["noise"]["floor_n"] = p.noise_floor_n;
  root["noise"]["tau_s"] = p.noise_tau_s;
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << root;
  return std::string(out.c_str()) + "\n";
}

}  // namespace manip::sim
