#include "manip/control/config.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <set>
#include <sstream>

namespace manip::control {
namespace {

std::string scalar_text(const YAML::Node& n) {
  if (n.IsScalar()) return n.Scalar();
  std::ostringstream os;
  os << n;
  std::string s = os.str();
  for (auto& c : s)
    if (c == '\n') c = ' ';
  return s;
}

// Strict reader of one mapping: every access marks a key as known; finish()
// rejects the keys that were never asked for.
class Section {
 public:
  Section(const std::string& file, const YAML::Node& node, std::string path)
      : file_(file), node_(node), path_(std::move(path)) {
    if (!node_.IsMap()) fail_node(node_, path_.empty() ? "(top level)" : path_, "must be a mapping of keys");
  }

  [[noreturn]] void fail_node(const YAML::Node& n, const std::string& key, const std::string& why) const {
    std::ostringstream os;
    os << file_;
    if (n.IsDefined() && n.Mark().line >= 0) os << ':' << n.Mark().line + 1;
    os << ": " << key << ": " << why;
    throw ConfigError(os.str());
  }
  [[noreturn]] void fail(const std::string& key, const std::string& why) const {
    const YAML::Node n = node_[key];
    if (n.IsDefined()) fail_node(n, full(key), why);
    fail_node(node_, full(key), why);
  }

  std::string full(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

  YAML::Node get(const std::string& key, bool required = true) {
    known_.insert(key);
    YAML::Node n = node_[key];
    if (!n.IsDefined() || n.IsNull()) {
      if (required) fail_node(node_, full(key), "missing (required key)");
      return YAML::Node();
    }
    return n;
  }

  bool has(const std::string& key) {
    known_.insert(key);
    const YAML::Node n = node_[key];
    return n.IsDefined() && !n.IsNull();
  }

  Section sub(const std::string& key) { return Section(file_, get(key), full(key)); }

  double number(const std::string& key, const std::function<bool(double)>& ok, const char* rule) {
    const YAML::Node n = get(key);
    double v{};
    if (!n.IsScalar() || !YAML::convert<double>::decode(n, v) || !std::isfinite(v))
      fail_node(n, full(key), "expected a finite number, got '" + scalar_text(n) + "'");
    if (!ok(v)) fail_node(n, full(key), std::string(rule) + " (got " + scalar_text(n) + ")");
    return v;
  }
  double positive(const std::string& key) {
    return number(key, [](double v) { return v > 0; }, "must be > 0");
  }
  double nonneg(const std::string& key) {
    return number(key, [](double v) { return v >= 0; }, "must be >= 0");
  }
  long long integer(const std::string& key, long long lo, long long hi) {
    const YAML::Node n = get(key);
    long long v{};
    if (!n.IsScalar() || !YAML::convert<long long>::decode(n, v))
      fail_node(n, full(key), "expected an integer, got '" + scalar_text(n) + "'");
    if (v < lo || v > hi)
      fail_node(n, full(key),
                "must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "] (got " + std::to_string(v) + ")");
    return v;
  }
  std::uint64_t unsigned64(const std::string& key) {
    const YAML::Node n = get(key);
    unsigned long long v{};
    if (!n.IsScalar() || !YAML::convert<unsigned long long>::decode(n, v) || (!n.Scalar().empty() && n.Scalar()[0] == '-'))
      fail_node(n, full(key), "expected a non-negative integer, got '" + scalar_text(n) + "'");
    return v;
  }
  bool boolean(const std::string& key) {
    const YAML::Node n = get(key);
    bool v{};
    if (!n.IsScalar() || !YAML::convert<bool>::decode(n, v))
      fail_node(n, full(key), "expected true or false, got '" + scalar_text(n) + "'");
    return v;
  }
  std::string string(const std::string& key, bool allow_empty = false) {
    const YAML::Node n = get(key);
    if (!n.IsScalar()) fail_node(n, full(key), "expected a string");
    if (!allow_empty && n.Scalar().empty()) fail_node(n, full(key), "must not be empty");
    return n.Scalar();
  }
  std::string choice(const std::string& key, const std::vector<std::string>& allowed) {
    const std::string v = string(key);
    for (const auto& a : allowed)
      if (a == v) return v;
    std::string list;
    for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
    fail(key, "must be one of " + list + " (got '" + v + "')");
  }
  std::vector<double> numbers(const std::string& key, std::size_t n_expected /*0 = any >= 1*/) {
    const YAML::Node n = get(key);
    if (!n.IsSequence()) fail_node(n, full(key), "expected a list of numbers");
    if (n_expected && n.size() != n_expected)
      fail_node(n, full(key), "expected " + std::to_string(n_expected) + " numbers, got " + std::to_string(n.size()));
    if (!n_expected && n.size() == 0) fail_node(n, full(key), "expected at least one number");
    std::vector<double> out;
    for (std::size_t i = 0; i < n.size(); ++i) {
      double v{};
      if (!n[i].IsScalar() || !YAML::convert<double>::decode(n[i], v) || !std::isfinite(v))
        fail_node(n[i], full(key), "element " + std::to_string(i) + " is not a finite number ('" +
                                       scalar_text(n[i]) + "')");
      out.push_back(v);
    }
    return out;
  }
  Vec2 vec2(const std::string& key, const std::function<bool(double)>& ok = nullptr, const char* rule = "") {
    const auto v = numbers(key, 2);
    if (ok)
      for (double x : v)
        if (!ok(x)) fail(key, std::string("every element ") + rule + " (got " + scalar_text(node_[key]) + ")");
    return Vec2(v[0], v[1]);
  }
  Vec2 vec2_positive(const std::string& key) {
    return vec2(key, [](double v) { return v > 0; }, "must be > 0");
  }
  Vec2 vec2_nonneg(const std::string& key) {
    return vec2(key, [](double v) { return v >= 0; }, "must be >= 0");
  }
  Mat2 mat2(const std::string& key) {
    const YAML::Node n = get(key);
    if (!n.IsSequence() || n.size() != 2 || !n[0].IsSequence() || !n[1].IsSequence() || n[0].size() != 2 ||
        n[1].size() != 2)
      fail_node(n, full(key), "expected a 2x2 matrix [[a, b], [c, d]] (row-major, shoulder frame)");
    Mat2 m;
    for (int r = 0; r < 2; ++r)
      for (int c = 0; c < 2; ++c) {
        double v{};
        if (!YAML::convert<double>::decode(n[r][c], v) || !std::isfinite(v))
          fail_node(n, full(key), "element (" + std::to_string(r) + "," + std::to_string(c) + ") is not a finite number");
        m(r, c) = v;
      }
    return m;
  }
  Mat2 mat2_spd(const std::string& key) {
    const Mat2 m = mat2(key);
    const Mat2 s = 0.5 * (m + m.transpose());
    if (!(s(0, 0) > 0 && s.determinant() > 0)) fail(key, "must be positive definite");
    return m;
  }

  void finish() const {
    for (auto it = node_.begin(); it != node_.end(); ++it) {
      const std::string k = it->first.as<std::string>();
      if (!known_.count(k)) {
        std::string list;
        for (const auto& a : known_) list += (list.empty() ? "" : ", ") + a;
        fail_node(it->first, full(k), "unknown key (known keys here: " + list + ")");
      }
    }
  }

 private:
  const std::string& file_;
  YAML::Node node_;
  std::string path_;
  std::set<std::string> known_;
};

void apply_override(YAML::Node root, const std::string& path, const std::string& value, const std::string& name) {
  std::vector<std::string> parts;
  std::stringstream ss(path);
  std::string p;
  while (std::getline(ss, p, '.')) parts.push_back(p);
  if (parts.empty()) throw ConfigError(name + ": override with empty key");
  YAML::Node n = root;
  for (std::size_t i = 0; i + 1 < parts.size(); ++i) {
    if (!n[parts[i]].IsMap()) throw ConfigError(name + ": override " + path + ": no section " + parts[i]);
    n.reset(n[parts[i]]);
  }
  n[parts.back()] = YAML::Load(value);
}

RtConfig parse_node(const YAML::Node& root, const std::string& file) {
  RtConfig c;
  Section top(file, root, "");

  {
    auto s = top.sub("participant");
    auto& p = c.participant;
    p.participant_id = s.string("participant_id");
    p.session_id = s.string("session_id");
    p.body_mass_kg = s.nonneg("body_mass_kg");
    p.body_height_m = s.nonneg("body_height_m");
    const Vec2 l = s.vec2_positive("segment_length_m");
    const Vec2 m = s.vec2_positive("segment_mass_kg");
    const Vec2 com = s.vec2_positive("segment_com_m");
    const Vec2 in = s.vec2_positive("segment_inertia_kgm2");
    for (int i = 0; i < 2; ++i) {
      p.segment_length_m[i] = l[i];
      p.segment_mass_kg[i] = m[i];
      p.segment_com_m[i] = com[i];
      p.segment_inertia_kgm2[i] = in[i];
      if (com[i] >= l[i]) s.fail("segment_com_m", "centre of mass must lie within the segment (com < length)");
    }
    s.finish();
  }
  {
    auto s = top.sub("frames");
    c.frames.origin_in_shoulder_m = s.vec2("workspace_origin_in_shoulder_m");
    c.frames.rot_rad = s.number("workspace_to_shoulder_rot_rad", [](double v) { return std::abs(v) <= 3.1416; },
                                "must be within [-pi, pi]");
    s.finish();
  }
  {
    auto s = top.sub("loop");
    auto& l = c.loop;
    l.sample_rate_hz = s.number("sample_rate_hz", [](double v) { return v >= 100 && v <= 20000; },
                                "must be in [100, 20000] Hz");
    l.drive_rate_hz = s.number("drive_rate_hz", [](double v) { return v > 0; }, "must be > 0");
    const double dec = l.sample_rate_hz / l.drive_rate_hz;
    if (dec < 1.0 || std::abs(dec - std::round(dec)) > 1e-9)
      s.fail("drive_rate_hz", "must divide sample_rate_hz into a whole number of cycles (e.g. 4000/2000)");
    if (std::abs(1e6 / l.sample_rate_hz - std::round(1e6 / l.sample_rate_hz)) > 1e-9)
      s.fail("sample_rate_hz", "the period must be a whole number of microseconds (state_t.utime)");
    l.priority = static_cast<int>(s.integer("priority", 1, 99));
    l.cpu = static_cast<int>(s.integer("cpu", -1, 1023));
    l.prefault_stack_bytes = static_cast<std::size_t>(s.integer("prefault_stack_bytes", 0, 64ll << 20));
    l.log_queue_capacity = static_cast<std::size_t>(s.integer("log_queue_capacity", 1024, 1ll << 24));
    l.bus_queue_capacity = static_cast<std::size_t>(s.integer("bus_queue_capacity", 64, 1ll << 22));
    l.command_queue_capacity = static_cast<std::size_t>(s.integer("command_queue_capacity", 4, 1 << 16));
    l.max_commands_per_cycle = static_cast<int>(s.integer("max_commands_per_cycle", 1, 64));
    l.overrun_policy = s.choice("overrun_policy", {"catch_up", "reanchor"}) == "catch_up" ? OverrunPolicy::kCatchUp
                                                                                          : OverrunPolicy::kReanchor;
    l.max_catch_up_cycles = static_cast<int>(s.integer("max_catch_up_cycles", 0, 1000));
    l.overrun_fault_consecutive = static_cast<int>(s.integer("overrun_fault_consecutive", 1, 1000000));
    l.overrun_fault_per_second = static_cast<int>(s.integer("overrun_fault_per_second", 1, 1000000));
    s.finish();
  }
  {
    auto s = top.sub("admittance");
    c.admittance.m_adm_kg = s.vec2_positive("m_adm_kg");
    c.admittance.d_adm_nspm = s.vec2_nonneg("d_adm_nspm");
    s.finish();
  }
  {
    auto s = top.sub("handle");
    c.handle_mass_kg = s.vec2_nonneg("mass_kg");
    s.finish();
  }
  {
    auto s = top.sub("pd");
    c.pd.kp_npm = s.vec2_positive("kp_npm");
    c.pd.kd_nspm = s.vec2_nonneg("kd_nspm");
    c.pd.ff_mass_kg = s.vec2_nonneg("ff_mass_kg");
    c.pd.ff_viscous_nspm = s.vec2_nonneg("ff_viscous_nspm");
    c.pd.ff_sensor_force_gain = s.number("ff_sensor_force_gain", [](double v) { return v >= 0 && v <= 1; },
                                         "must be in [0, 1]");
    s.finish();
  }
  {
    auto s = top.sub("safety");
    auto& f = c.safety;
    f.workspace_limit_m = s.number("workspace_limit_m", [](double v) { return v > 0 && v <= 0.15; },
                                   "must be in (0, 0.15] m (stage travel is +-0.15 m)");
    f.wall_start_m = s.positive("wall_start_m");
    if (f.wall_start_m >= f.workspace_limit_m) s.fail("wall_start_m", "must be < safety.workspace_limit_m");
    f.wall_stiffness_npm = s.nonneg("wall_stiffness_npm");
    f.wall_damping_nspm = s.nonneg("wall_damping_nspm");
    f.max_velocity_mps = s.positive("max_velocity_mps");
    f.max_handle_force_n = s.positive("max_handle_force_n");
    f.sensor_saturation_n = s.positive("sensor_saturation_n");
    f.max_motor_force_n = s.positive("max_motor_force_n");
    f.max_pert_amplitude_n = s.positive("max_pert_amplitude_n");
    f.max_tracking_error_m = s.positive("max_tracking_error_m");
    f.stale_cycles = static_cast<int>(s.integer("stale_cycles", 1, 4000));
    f.safe_law = s.choice("safe_law", {"zero_force", "damping"}) == "damping" ? SafeLaw::kDamping : SafeLaw::kZeroForce;
    f.safe_damping_nspm = s.nonneg("safe_damping_nspm");
    f.fault_history_cycles = static_cast<int>(s.integer("fault_history_cycles", 1, 40000));
    f.shutdown_cycles = static_cast<int>(s.integer("shutdown_cycles", 1, 40000));
    s.finish();
  }
  {
    auto s = top.sub("perturbation");
    auto& p = c.perturbation;
    p.duration_s = s.number("duration_s", [](double v) { return v > 0 && v <= 2.0; }, "must be in (0, 2] s");
    p.amplitude_n = s.nonneg("amplitude_n");
    if (p.amplitude_n > c.safety.max_pert_amplitude_n)
      s.fail("amplitude_n", "exceeds safety.max_pert_amplitude_n (" + std::to_string(c.safety.max_pert_amplitude_n) + " N)");
    p.trigger_x2_shoulder_m = s.number("trigger_x2_shoulder_m", [](double) { return true; }, "");
    p.angles_deg = s.numbers("angles_deg", 0);
    p.repeats_per_angle = static_cast<int>(s.integer("repeats_per_angle", 0, 1000));
    s.finish();
  }
  {
    auto s = top.sub("protocol");
    auto& p = c.protocol;
    p.movements = static_cast<int>(s.integer("movements", 1, 100000));
    if (s.has("perturbed_trials"))
      p.perturbed_trials = static_cast<int>(s.integer("perturbed_trials", 0, 100000));
    else
      p.perturbed_trials = -1;
    p.seed = s.unsigned64("seed");
    p.autostart = s.boolean("autostart");
    p.start_shoulder_m = s.vec2("start_shoulder_m");
    p.goal_shoulder_m = s.vec2("goal_shoulder_m");
    p.target_radius_m = s.positive("target_radius_m");
    p.rest_speed_mps = s.positive("rest_speed_mps");
    p.start_hold_s = s.nonneg("start_hold_s");
    p.goal_hold_s = s.nonneg("goal_hold_s");
    p.trial_timeout_s = s.positive("trial_timeout_s");
    p.max_requeues = static_cast<int>(s.integer("max_requeues", 0, 100));
    const int perturbed = p.perturbed_trials < 0 ? c.perturbation.full_set() : p.perturbed_trials;
    if (p.perturbed_trials > c.perturbation.full_set())
      s.fail("perturbed_trials", "exceeds the perturbation design (angles x repeats = " +
                                     std::to_string(c.perturbation.full_set()) + ")");
    if (perturbed > p.movements)
      s.fail("movements", "fewer movements (" + std::to_string(p.movements) + ") than perturbed trials (" +
                              std::to_string(perturbed) + ")");
    // Targets must be reachable inside the virtual walls, and the trigger between them.
    for (const auto* key : {"start_shoulder_m", "goal_shoulder_m"}) {
      const Vec2 t = std::string(key) == "start_shoulder_m" ? p.start_shoulder_m : p.goal_shoulder_m;
      const Vec2 w = c.frames.point_to_workspace(t);
      if (std::abs(w.x()) + p.target_radius_m > c.safety.wall_start_m + 1e-9 ||
          std::abs(w.y()) + p.target_radius_m > c.safety.wall_start_m + 1e-9)
        s.fail(key, "target (with its radius) lies outside the virtual walls of the workspace (workspace frame: " +
                        std::to_string(w.x()) + ", " + std::to_string(w.y()) + " m)");
    }
    if ((p.goal_shoulder_m - p.start_shoulder_m).norm() < 2 * p.target_radius_m)
      s.fail("goal_shoulder_m", "start and goal targets overlap");
    const double trig = c.perturbation.trigger_x2_shoulder_m;
    if (perturbed > 0 && !((trig - p.start_shoulder_m.y()) * (trig - p.goal_shoulder_m.y()) < 0))
      s.fail("goal_shoulder_m", "perturbation.trigger_x2_shoulder_m must lie strictly between start and goal x2");
    s.finish();
  }
  {
    auto s = top.sub("logger");
    c.logger.flush_interval_s = s.positive("flush_interval_s");
    s.finish();
  }
  {
    auto s = top.sub("bus");
    c.bus.lcm_url = s.string("lcm_url");
    c.bus.state_rate_hz = s.positive("state_rate_hz");
    if (c.bus.state_rate_hz > c.loop.sample_rate_hz) s.fail("state_rate_hz", "must not exceed loop.sample_rate_hz");
    c.bus.health_rate_hz = s.number("health_rate_hz", [](double v) { return v > 0 && v <= 100; }, "must be in (0, 100]");
    c.bus.subscription_queue_capacity = static_cast<int>(s.integer("subscription_queue_capacity", 1, 1000000));
    s.finish();
  }
  {
    auto s = top.sub("sim");
    auto& m = c.sim;
    m.stage_mass_kg = s.vec2_positive("stage_mass_kg");
    m.viscous_nspm = s.vec2_nonneg("viscous_nspm");
    m.coulomb_n = s.vec2_nonneg("coulomb_n");
    m.coulomb_velocity_mps = s.positive("coulomb_velocity_mps");
    m.encoder_resolution_m = s.nonneg("encoder_resolution_m");
    m.force_noise_n = s.nonneg("force_noise_n");
    m.drive_peak_force_n = s.positive("drive_peak_force_n");
    m.substeps = static_cast<int>(s.integer("substeps", 1, 64));
    m.seed = s.unsigned64("seed");
    {
      auto h = s.sub("human");
      auto& u = m.human;
      u.model = h.choice("model", {"linear", "neuromech"});
      if (h.has("arm_config")) u.arm_config = h.string("arm_config");
      u.m_kg = h.mat2_spd("m_kg");
      u.d_nspm = h.mat2("d_nspm");
      u.k_npm = h.mat2("k_npm");
      u.m_load_kg = h.mat2("m_load_kg");
      u.d_load_nspm = h.mat2("d_load_nspm");
      u.voluntary_delay_s = h.positive("voluntary_delay_s");
      u.k_voluntary_npm = h.mat2("k_voluntary_npm");
      u.d_voluntary_nspm = h.mat2("d_voluntary_nspm");
      u.motor_noise_n = h.nonneg("motor_noise_n");
      u.motor_noise_tau_s = h.positive("motor_noise_tau_s");
      h.finish();
    }
    {
      auto h = s.sub("participant");
      auto& u = m.participant;
      u.reaction_time_s = h.nonneg("reaction_time_s");
      u.reaction_time_jitter_s = h.nonneg("reaction_time_jitter_s");
      if (u.reaction_time_jitter_s > u.reaction_time_s)
        h.fail("reaction_time_jitter_s", "must not exceed reaction_time_s");
      u.reach_duration_s = h.positive("reach_duration_s");
      u.reach_duration_jitter_s = h.nonneg("reach_duration_jitter_s");
      if (u.reach_duration_jitter_s >= u.reach_duration_s)
        h.fail("reach_duration_jitter_s", "must be < reach_duration_s");
      u.return_duration_s = h.positive("return_duration_s");
      u.lateral_bow_std_m = h.nonneg("lateral_bow_std_m");
      h.finish();
    }
    s.finish();
  }
  top.finish();
  return c;
}

}  // namespace

int LoopConfig::drive_decimation() const {
  return static_cast<int>(std::lround(sample_rate_hz / drive_rate_hz));
}

RtConfig parse_rt_config(const std::string& yaml_text, const std::string& name, const ConfigOverrides& overrides) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    throw ConfigError(name + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + e.msg);
  }
  if (!root.IsMap()) throw ConfigError(name + ": expected a YAML mapping at the top level");
  std::string effective = yaml_text;
  if (!overrides.empty()) {
    std::string list;
    for (const auto& [k, v] : overrides) {
      try {
        apply_override(root, k, v, name);
      } catch (const YAML::Exception& e) {
        throw ConfigError(name + ": override " + k + "=" + v + ": " + e.msg);
      }
      list += (list.empty() ? "" : ", ") + k + "=" + v;
    }
    YAML::Emitter em;
    em << root;
    effective = "# effective configuration: " + name + " with command-line overrides " + list + "\n" + em.c_str() + "\n";
  }
  RtConfig c;
  try {
    c = parse_node(root, name);
  } catch (const YAML::Exception& e) {
    throw ConfigError(name + ":" + std::to_string(e.mark.line + 1) + ": " + e.msg);
  }
  c.source_name = name;
  c.effective_yaml = std::move(effective);
  return c;
}

RtConfig load_rt_config(const std::string& path, const ConfigOverrides& overrides) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ConfigError(path + ": cannot read the configuration file");
  std::ostringstream os;
  os << in.rdbuf();
  return parse_rt_config(os.str(), path, overrides);
}

ConfigOverrides trials_overrides(const RtConfig& cfg, int n_movements) {
  const int full = cfg.perturbed_count();
  const int k = static_cast<int>(std::lround(static_cast<double>(n_movements) * full / cfg.protocol.movements));
  return {{"protocol.movements", std::to_string(n_movements)}, {"protocol.perturbed_trials", std::to_string(k)}};
}

}  // namespace manip::control
