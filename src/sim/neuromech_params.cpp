// NeuromechParams: validation, strict YAML loading and emitting.
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <numbers>
#include <sstream>
#include <stdexcept>

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

std::string where(const YAML::Exception& e) {
  return e.mark.is_null() ? std::string() : ":" + std::to_string(e.mark.line + 1);
}

// Strict reader: every key required, unknown keys rejected, errors name file and key.
class Reader {
 public:
  explicit Reader(std::string file) : file_(std::move(file)) {}

  [[noreturn]] void fail(const std::string& key, const std::string& why) const {
    throw std::runtime_error(file_ + ": " + key + ": " + why);
  }

  static std::string join(const std::string& path, const char* key) {
    return path.empty() ? std::string(key) : path + "." + key;
  }

  // Checks that `node` (at `path`) is a map with exactly the keys `allowed`.
  void expect_keys(const YAML::Node& node, const std::string& path, std::initializer_list<const char*> allowed) const {
    if (!node.IsMap()) fail(path.empty() ? "<top level>" : path, "expected a map of keys");
    for (const auto& kv : node) {
      const auto k = kv.first.as<std::string>();
      const bool known = std::any_of(allowed.begin(), allowed.end(), [&](const char* a) { return k == a; });
      if (!known) {
        std::string list;
        for (const char* a : allowed) list += (list.empty() ? "" : ", ") + std::string(a);
        fail(join(path, k.c_str()), "unknown key (expected one of: " + list + ")");
      }
    }
    for (const char* a : allowed)
      if (!node[a]) fail(join(path, a), "missing");
  }

  double number(const YAML::Node& node, const std::string& key) const {
    if (!node.IsScalar()) fail(key, "expected a number");
    try {
      return node.as<double>();
    } catch (const YAML::Exception&) {
      fail(key, "'" + node.Scalar() + "' is not a number");
    }
  }

  bool boolean(const YAML::Node& node, const std::string& key) const {
    if (!node.IsScalar()) fail(key, "expected true or false");
    try {
      return node.as<bool>();
    } catch (const YAML::Exception&) {
      fail(key, "'" + node.Scalar() + "' is not true or false");
    }
  }

  template <int N>
  Eigen::Matrix<double, N, 1> vec(const YAML::Node& node, const std::string& key) const {
    if (!node.IsSequence() || node.size() != static_cast<std::size_t>(N))
      fail(key, "expected a list of " + std::to_string(N) + " numbers");
    Eigen::Matrix<double, N, 1> v;
    for (int i = 0; i < N; ++i) v(i) = number(node[static_cast<std::size_t>(i)], key + "[" + std::to_string(i) + "]");
    return v;
  }

 private:
  std::string file_;
};

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
  YAML::Node root;
  try {
    root = YAML::LoadFile(yaml_path);
  } catch (const YAML::BadFile&) {
    throw std::runtime_error(yaml_path + ": cannot open the file");
  } catch (const YAML::Exception& e) {
    throw std::runtime_error(yaml_path + where(e) + ": YAML syntax error: " + e.msg);
  }
  const Reader r(yaml_path);
  NeuromechParams p;
  try {
    r.expect_keys(root, "", {"integration", "anthropometrics", "muscles", "feedforward", "feedback", "noise"});

    r.expect_keys(root["integration"], "integration", {"step_s", "session_step_s"});
    p.step_s = r.number(root["integration"]["step_s"], "integration.step_s");
    p.session_step_s = r.number(root["integration"]["session_step_s"], "integration.session_step_s");

    r.expect_keys(root["anthropometrics"], "anthropometrics", {"upper_arm", "forearm"});
    for (int i = 0; i < 2; ++i) {
      const std::string path = std::string("anthropometrics.") + kSegments[i];
      const YAML::Node s = root["anthropometrics"][kSegments[i]];
      r.expect_keys(s, path, {"length_m", "mass_kg", "com_m", "inertia_kgm2"});
      p.anthropometrics.length_m[i] = r.number(s["length_m"], path + ".length_m");
      p.anthropometrics.mass_kg[i] = r.number(s["mass_kg"], path + ".mass_kg");
      p.anthropometrics.com_m[i] = r.number(s["com_m"], path + ".com_m");
      p.anthropometrics.inertia_kgm2[i] = r.number(s["inertia_kgm2"], path + ".inertia_kgm2");
    }

    const YAML::Node mu = root["muscles"];
    r.expect_keys(mu, "muscles",
                  {"moment_arms_m", "k0_npm", "k1_per_m", "stiffness_to_damping_per_s", "tonic_activation_n"});
    r.expect_keys(mu["moment_arms_m"], "muscles.moment_arms_m", {"shoulder", "elbow"});
    p.moment_arms_m.row(0) = r.vec<kMuscles>(mu["moment_arms_m"]["shoulder"], "muscles.moment_arms_m.shoulder");
    p.moment_arms_m.row(1) = r.vec<kMuscles>(mu["moment_arms_m"]["elbow"], "muscles.moment_arms_m.elbow");
    p.k0_npm = r.vec<kMuscles>(mu["k0_npm"], "muscles.k0_npm");
    p.k1_per_m = r.vec<kMuscles>(mu["k1_per_m"], "muscles.k1_per_m");
    p.stiffness_to_damping_per_s = r.number(mu["stiffness_to_damping_per_s"], "muscles.stiffness_to_damping_per_s");
    p.tonic_activation_n = r.vec<kMuscles>(mu["tonic_activation_n"], "muscles.tonic_activation_n");

    const YAML::Node ff = root["feedforward"];
    r.expect_keys(ff, "feedforward", {"enabled", "load_mass_kg", "load_damping_nspm"});
    p.feedforward_enabled = r.boolean(ff["enabled"], "feedforward.enabled");
    p.load_mass_kg = r.vec<2>(ff["load_mass_kg"], "feedforward.load_mass_kg");
    p.load_damping_nspm = r.vec<2>(ff["load_damping_nspm"], "feedforward.load_damping_nspm");

    const YAML::Node fb = root["feedback"];
    r.expect_keys(fb, "feedback", {"short_latency", "long_latency", "voluntary"});
    for (int i = 0; i < kPathways; ++i) {
      const char* name = pathway_name(static_cast<Pathway>(i));
      const std::string path = std::string("feedback.") + name;
      const YAML::Node n = fb[name];
      r.expect_keys(n, path, {"enabled", "delay_s", "kp_npm", "kd_nspm"});
      auto& f = p.feedback[static_cast<std::size_t>(i)];
      f.enabled = r.boolean(n["enabled"], path + ".enabled");
      f.delay_s = r.number(n["delay_s"], path + ".delay_s");
      f.kp_npm = r.number(n["kp_npm"], path + ".kp_npm");
      f.kd_nspm = r.number(n["kd_nspm"], path + ".kd_nspm");
    }

    const YAML::Node no = root["noise"];
    r.expect_keys(no, "noise", {"cv", "floor_n", "tau_s"});
    p.noise_cv = r.number(no["cv"], "noise.cv");
    p.noise_floor_n = r.number(no["floor_n"], "noise.floor_n");
    p.noise_tau_s = r.number(no["tau_s"], "noise.tau_s");
  } catch (const YAML::Exception& e) {  // anything the strict reader did not anticipate
    throw std::runtime_error(yaml_path + where(e) + ": " + e.msg);
  }
  if (auto why = p.invalid_reason()) throw std::runtime_error(yaml_path + ": " + *why);
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
