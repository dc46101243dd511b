#include "manip/runtime/config.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <sstream>

#include "manip/common/yaml_reader.hpp"
#include "manip/version.hpp"

namespace manip::runtime {
namespace {

using control::SafeLaw;
using yaml::Section;

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
    auto& p = c.session;
    p.participant_id = s.string("participant_id");
    p.session_id = s.string("session_id");
    p.body_mass_kg = s.nonneg("body_mass_kg");
    p.body_height_m = s.nonneg("body_height_m");
    auto& a = p.anthropometrics;
    const Vec2 l = s.vec2_positive("segment_length_m");
    const Vec2 m = s.vec2_positive("segment_mass_kg");
    const Vec2 com = s.vec2_positive("segment_com_m");
    const Vec2 in = s.vec2_positive("segment_inertia_kgm2");
    for (int i = 0; i < 2; ++i) {
      a.length_m[i] = l[i];
      a.mass_kg[i] = m[i];
      a.com_m[i] = com[i];
      a.inertia_kgm2[i] = in[i];
      if (com[i] >= l[i]) s.fail("segment_com_m", "centre of mass must lie within the segment (com < length)");
    }
    s.finish();
  }
  {
    auto s = top.sub("frames");
    c.session.frame.origin_in_shoulder_m = s.vec2("workspace_origin_in_shoulder_m");
    c.session.frame.rot_rad = s.number("workspace_to_shoulder_rot_rad", [](double v) { return std::abs(v) <= 3.1416; },
                                "must be within [-pi, pi]");
    s.finish();
  }
  {
    auto s = top.sub("loop");
    auto& l = c.loop;
    auto& ses = c.session;
    ses.sample_rate_hz = s.number("sample_rate_hz", [](double v) { return v >= 100 && v <= 20000; },
                                  "must be in [100, 20000] Hz");
    ses.drive_rate_hz = s.number("drive_rate_hz", [](double v) { return v > 0; }, "must be > 0");
    const double dec = ses.sample_rate_hz / ses.drive_rate_hz;
    if (dec < 1.0 || std::abs(dec - std::round(dec)) > 1e-9)
      s.fail("drive_rate_hz", "must divide sample_rate_hz into a whole number of cycles (e.g. 4000/2000)");
    if (std::abs(1e6 / ses.sample_rate_hz - std::round(1e6 / ses.sample_rate_hz)) > 1e-9)
      s.fail("sample_rate_hz", "the period must be a whole number of microseconds (state_t.utime)");
    l.priority = static_cast<int>(s.integer("priority", 1, 99));
    l.cpu = static_cast<int>(s.integer("cpu", -1, 1023));
    l.prefault_stack_bytes = static_cast<std::size_t>(s.integer("prefault_stack_bytes", 0, 64ll << 20));
    l.log_queue_capacity = static_cast<std::size_t>(s.integer("log_queue_capacity", 1024, 1ll << 24));
    l.bus_queue_capacity = static_cast<std::size_t>(s.integer("bus_queue_capacity", 64, 1ll << 22));
    l.command_queue_capacity = static_cast<std::size_t>(s.integer("command_queue_capacity", 4, 1 << 16));
    c.cycle.max_commands_per_cycle = static_cast<int>(s.integer("max_commands_per_cycle", 1, 64));
    l.overrun_policy = s.choice("overrun_policy", {"catch_up", "reanchor"}) == "catch_up" ? OverrunPolicy::kCatchUp
                                                                                          : OverrunPolicy::kReanchor;
    l.max_catch_up_cycles = static_cast<int>(s.integer("max_catch_up_cycles", 0, 1000));
    c.cycle.overrun_fault_consecutive = static_cast<int>(s.integer("overrun_fault_consecutive", 1, 1000000));
    c.cycle.overrun_fault_per_second = static_cast<int>(s.integer("overrun_fault_per_second", 1, 1000000));
    s.finish();
  }
  {
    auto s = top.sub("admittance");
    c.session.m_adm_kg = s.vec2_positive("m_adm_kg");
    c.session.d_adm_nspm = s.vec2_nonneg("d_adm_nspm");
    s.finish();
  }
  {
    auto s = top.sub("handle");
    c.session.m_handle_kg = s.vec2_nonneg("mass_kg");
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
    auto& d = c.session.perturbation;
    d.duration_s = s.number("duration_s", [](double v) { return v > 0 && v <= 2.0; }, "must be in (0, 2] s");
    d.amplitude_n = s.nonneg("amplitude_n");
    if (d.amplitude_n > c.safety.max_pert_amplitude_n)
      s.fail("amplitude_n", "exceeds safety.max_pert_amplitude_n (" + std::to_string(c.safety.max_pert_amplitude_n) + " N)");
    d.trigger_x2_shoulder_m = s.any_number("trigger_x2_shoulder_m");
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
      const Vec2 w = c.session.frame.point_to_workspace(t);
      if (std::abs(w.x()) + p.target_radius_m > c.safety.wall_start_m + 1e-9 ||
          std::abs(w.y()) + p.target_radius_m > c.safety.wall_start_m + 1e-9)
        s.fail(key, "target (with its radius) lies outside the virtual walls of the workspace (workspace frame: " +
                        std::to_string(w.x()) + ", " + std::to_string(w.y()) + " m)");
    }
    if ((p.goal_shoulder_m - p.start_shoulder_m).norm() < 2 * p.target_radius_m)
      s.fail("goal_shoulder_m", "start and goal targets overlap");
    const double trig = c.session.perturbation.trigger_x2_shoulder_m;
    if (perturbed > 0 && !((trig - p.start_shoulder_m.y()) * (trig - p.goal_shoulder_m.y()) < 0))
      s.fail("goal_shoulder_m", "perturbation.trigger_x2_shoulder_m must lie strictly between start and goal x2");
    s.finish();
  }
  {
    auto s = top.sub("logger");
    c.logger.flush_interval_s = s.positive("flush_interval_s");
    if (s.has("flush_every_cycles")) c.logger.flush_every_cycles = s.integer("flush_every_cycles", 1, 100'000'000);
    s.finish();
  }
  {
    auto s = top.sub("bus");
    c.bus.lcm_url = s.string("lcm_url");
    c.cycle.live_state_rate_hz = s.positive("state_rate_hz");
    if (c.cycle.live_state_rate_hz > c.session.sample_rate_hz) s.fail("state_rate_hz", "must not exceed loop.sample_rate_hz");
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


schema::SessionDescription default_session() {
  schema::SessionDescription d;
  d.software_version = manip::kVersion;
  d.participant_id = "sim-001";
  d.session_id = "sim-session-001";
  return d;
}

namespace {

// Appends "key" to `diff` when a != b and diff is still empty.
template <class T>
void cmp(std::string& diff, const char* key, const T& a, const T& b) {
  if (diff.empty() && !(a == b)) diff = key;
}
void cmp2(std::string& diff, const char* key, const double (&a)[2], const double (&b)[2]) {
  if (diff.empty() && (a[0] != b[0] || a[1] != b[1])) diff = key;
}

}  // namespace

std::string first_difference(const RtConfig& a, const RtConfig& b) {
  std::string d;
  const auto &sa = a.session, &sb = b.session;
  cmp(d, "participant.participant_id", sa.participant_id, sb.participant_id);
  cmp(d, "participant.session_id", sa.session_id, sb.session_id);
  cmp(d, "participant.body_mass_kg", sa.body_mass_kg, sb.body_mass_kg);
  cmp(d, "participant.body_height_m", sa.body_height_m, sb.body_height_m);
  cmp2(d, "participant.segment_length_m", sa.anthropometrics.length_m, sb.anthropometrics.length_m);
  cmp2(d, "participant.segment_mass_kg", sa.anthropometrics.mass_kg, sb.anthropometrics.mass_kg);
  cmp2(d, "participant.segment_com_m", sa.anthropometrics.com_m, sb.anthropometrics.com_m);
  cmp2(d, "participant.segment_inertia_kgm2", sa.anthropometrics.inertia_kgm2, sb.anthropometrics.inertia_kgm2);
  cmp(d, "frames.workspace_origin_in_shoulder_m", sa.frame.origin_in_shoulder_m, sb.frame.origin_in_shoulder_m);
  cmp(d, "frames.workspace_to_shoulder_rot_rad", sa.frame.rot_rad, sb.frame.rot_rad);
  cmp(d, "loop.sample_rate_hz", sa.sample_rate_hz, sb.sample_rate_hz);
  cmp(d, "loop.drive_rate_hz", sa.drive_rate_hz, sb.drive_rate_hz);
  cmp(d, "admittance.m_adm_kg", sa.m_adm_kg, sb.m_adm_kg);
  cmp(d, "admittance.d_adm_nspm", sa.d_adm_nspm, sb.d_adm_nspm);
  cmp(d, "handle.mass_kg", sa.m_handle_kg, sb.m_handle_kg);
  cmp(d, "perturbation.duration_s", sa.perturbation.duration_s, sb.perturbation.duration_s);
  cmp(d, "perturbation.amplitude_n", sa.perturbation.amplitude_n, sb.perturbation.amplitude_n);
  cmp(d, "perturbation.trigger_x2_shoulder_m", sa.perturbation.trigger_x2_shoulder_m,
      sb.perturbation.trigger_x2_shoulder_m);
  cmp(d, "session.schema_version", sa.schema_version, sb.schema_version);
  // The law's and the runtime's sections: defaulted operator== per struct
  // (every member), so a field added later is compared without touching this.
  cmp(d, "loop (cycle part) / bus.state_rate_hz", a.cycle, b.cycle);
  cmp(d, "pd", a.pd, b.pd);
  cmp(d, "safety", a.safety, b.safety);
  cmp(d, "perturbation.angles_deg/repeats_per_angle", a.perturbation, b.perturbation);
  cmp(d, "protocol", a.protocol, b.protocol);
  cmp(d, "loop", a.loop, b.loop);
  cmp(d, "logger", a.logger, b.logger);
  cmp(d, "bus", a.bus, b.bus);
  cmp(d, "sim.human", a.sim.human, b.sim.human);
  cmp(d, "sim.participant", a.sim.participant, b.sim.participant);
  cmp(d, "sim", a.sim, b.sim);
  return d;
}

RtConfig parse_rt_config(const std::string& yaml_text, const std::string& name, const ConfigOverrides& overrides) {
  YAML::Node root = yaml::parse(yaml_text, name);
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
  return parse_rt_config(yaml::read_text_file(path), path, overrides);
}

ConfigOverrides trials_overrides(const RtConfig& cfg, int n_movements) {
  const int full = cfg.perturbed_count();
  const int k = static_cast<int>(std::lround(static_cast<double>(n_movements) * full / cfg.protocol.movements));
  return {{"protocol.movements", std::to_string(n_movements)}, {"protocol.perturbed_trials", std::to_string(k)}};
}

}  // namespace manip::runtime
