#include "manip/sim/hidden_effects.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>

#include "manip/common/errors.hpp"
#include "manip/common/rng.hpp"
#include "manip/sim/min_jerk.hpp"

namespace manip::sim {
namespace {
struct Named {
  const char* name;
  HiddenMechanism m;
  double max;  // plausible upper bound: refuses typos such as ms for s
};
constexpr Named kNames[] = {{"delay", HiddenMechanism::actuation_delay, 0.05},
                            {"friction", HiddenMechanism::stage_friction, 20.0},
                            {"handle", HiddenMechanism::handle_mass, 5.0},
                            {"reflex", HiddenMechanism::reflex, 3.0},
                            {"feedback", HiddenMechanism::feedback, 3.0},
                            {"reflex_dir", HiddenMechanism::reflex_dir, 3.0},
                            {"curl", HiddenMechanism::curl, 500.0},
                            {"sensor_lag", HiddenMechanism::sensor_lag, 0.02},
                            {"sensor_offset", HiddenMechanism::sensor_offset, 50.0},
                            {"sensor_drift", HiddenMechanism::sensor_drift, 1.0}};
}  // namespace

std::string to_string(HiddenMechanism m) {
  for (const auto& n : kNames)
    if (n.m == m) return n.name;
  return "?";
}

std::string to_string(const HiddenEffect& e) { return to_string(e.mechanism) + ":" + std::to_string(e.magnitude); }

HiddenEffect parse_hidden_effect(const std::string& text) {
  const auto colon = text.find(':');
  const std::string what = "--hidden '" + text + "'";
  if (colon == std::string::npos)
    throw UsageError(what + ": expected MECHANISM:MAGNITUDE (delay:0.002, friction:1, handle:0.3, reflex:0.5, feedback:0.5, "
                     "reflex_dir:1, curl:40, sensor_lag:0.001, sensor_offset:2, sensor_drift:0.05)");
  const std::string name = text.substr(0, colon), value = text.substr(colon + 1);
  for (const auto& n : kNames) {
    if (name != n.name) continue;
    double v = 0.0;
    std::size_t used = 0;
    try {
      v = std::stod(value, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != value.size() || !std::isfinite(v))
      throw UsageError(what + ": magnitude '" + value + "' is not a number");
    if (v < 0.0 || v > n.max)
      throw UsageError(what + ": magnitude must be in [0, " + std::to_string(n.max) + "] (SI units)");
    return HiddenEffect{n.m, v};
  }
  throw UsageError(what + ": unknown mechanism '" + name +
                   "' (delay, friction, handle, reflex, feedback, reflex_dir, curl, sensor_lag, sensor_offset, sensor_drift)");
}

HiddenEffectHuman::HiddenEffectHuman(const LinearHumanParams& person, std::vector<HiddenEffect> effects,
                                     const HiddenDraw& draw, double plant_step_s)
    : inner_([&] {
        LinearHumanParams p = person;
        p.sample_rate_hz = 1.0 / plant_step_s;
        return p;
      }()) {
  for (const auto& e : effects) {
    switch (e.mechanism) {
      case HiddenMechanism::handle_mass: break;  // in the plant (SessionDesign::hidden_handle_extra_kg)
      case HiddenMechanism::curl: curl_npm_ += (Mat2() << 0.0, e.magnitude, -e.magnitude, 0.0).finished(); break;
      case HiddenMechanism::stage_friction: break;  // in the plant (SessionDesign::hidden_stage_friction_n)
      case HiddenMechanism::reflex:
      case HiddenMechanism::feedback:
      case HiddenMechanism::reflex_dir: {
        const std::size_t i = e.mechanism == HiddenMechanism::reflex ? 0 : e.mechanism == HiddenMechanism::feedback ? 1 : 2;
        auto& c = delayed_[i];
        c.k_npm += e.magnitude * person.k_npm;
        c.d_nspm += e.magnitude * person.d_nspm;
        if (i == 2) c.one_sided = Vec2(std::cos(draw.reflex_direction_rad), std::sin(draw.reflex_direction_rad));
        break;
      }
      case HiddenMechanism::actuation_delay: break;  // in the plant (SessionDesign::actuation_delay_cycles)
      case HiddenMechanism::sensor_lag:              // in the force sensor (SessionDesign::hidden_sensor_*)
      case HiddenMechanism::sensor_offset:
      case HiddenMechanism::sensor_drift: break;
    }
  }
  const double delay_s[3] = {draw.reflex_delay_s, draw.feedback_delay_s, draw.reflex_delay_s};
  for (std::size_t i = 0; i < delayed_.size(); ++i)
    delayed_[i].ring.assign(static_cast<std::size_t>(std::max(1L, std::lround(delay_s[i] / plant_step_s))), {0.0, 0.0, 0.0, 0.0});
}

void HiddenEffectHuman::begin_trial(const ReachSpec& reach, std::uint64_t seed) {
  inner_.begin_trial(reach, seed);
  reach_ = reach;
  for (auto& c : delayed_) {
    for (auto& d : c.ring) d = {0.0, 0.0, 0.0, 0.0};
    c.head = 0;
  }
}

void HiddenEffectHuman::endpoint_dynamics(Mat2& m_x_kg, Vec2& h_n) {
  inner_.endpoint_dynamics(m_x_kg, h_n);
  const Vec2 x = inner_.hand_position_m();
  if (!curl_npm_.isZero()) {
    const auto plan = min_jerk(reach_.start_shoulder_m, reach_.goal_shoulder_m, reach_.t_start_s, reach_.duration_s,
                               reach_.lateral_bow_m, inner_.time_s());
    h_n += curl_npm_ * (plan.x - x);
  }
  for (const auto& c : delayed_) {
    if (c.k_npm.isZero()) continue;
    const auto& old = c.ring[c.head];  // oldest entry: the error one delay ago
    const Vec2 copy = c.k_npm * Vec2(old[0], old[1]) + c.d_nspm * Vec2(old[2], old[3]);
    // One-sided: a deviation along w (e = plan − hand against w) stretches the
    // group, which pulls back along −w; shortened, it adds nothing.
    h_n += c.one_sided.isZero() ? copy : Vec2(c.one_sided * std::min(0.0, c.one_sided.dot(copy)));
  }
}

void HiddenEffectHuman::advance(double dt_s, const Vec2& xdd_hand_mps2) {
  if (std::any_of(delayed_.begin(), delayed_.end(), [](const DelayedCopy& c) { return !c.k_npm.isZero(); })) {
    const auto plan = min_jerk(reach_.start_shoulder_m, reach_.goal_shoulder_m, reach_.t_start_s, reach_.duration_s,
                               reach_.lateral_bow_m, inner_.time_s());
    const Vec2 e = plan.x - inner_.hand_position_m(), ed = plan.xd - inner_.hand_velocity_mps();
    for (auto& c : delayed_) {
      c.ring[c.head] = {e.x(), e.y(), ed.x(), ed.y()};
      c.head = (c.head + 1) % c.ring.size();
    }
  }
  inner_.advance(dt_s, xdd_hand_mps2);
}

HiddenSession make_hidden_session(const SessionDesign& base, const LinearHumanParams& person0,
                                  const std::vector<HiddenEffect>& effects, std::uint64_t hidden_seed) {
  HiddenSession hs;
  hs.design = base;
  PortableRng rng(hidden_seed * 0x9E3779B97F4A7C15ull + 0x41D);
  hs.draw.session_seed = rng.next() % 1000000007ull + 1;
  hs.draw.impedance_scale = 0.85 + 0.30 * rng.uniform();
  hs.draw.reflex_delay_s = 0.025 + 0.010 * rng.uniform();
  hs.draw.feedback_delay_s = 0.060 + 0.040 * rng.uniform();  // after the other draws: they stay as they were
  hs.draw.reflex_direction_rad = 2.0 * std::numbers::pi * rng.uniform();  // likewise
  LinearHumanParams person = person0;
  person.d_nspm *= hs.draw.impedance_scale;
  person.k_npm *= hs.draw.impedance_scale;
  const double fs = base.session.sample_rate_hz;
  for (const auto& e : effects) {
    if (e.mechanism == HiddenMechanism::actuation_delay)
      hs.draw.actuation_delay_cycles += static_cast<int>(std::lround(e.magnitude * fs));
    if (e.mechanism == HiddenMechanism::handle_mass) hs.design.hidden_handle_extra_kg += e.magnitude;
    if (e.mechanism == HiddenMechanism::stage_friction) hs.design.hidden_stage_friction_n += e.magnitude;
    if (e.mechanism == HiddenMechanism::sensor_lag) hs.design.hidden_sensor_lag_s += e.magnitude;
    if (e.mechanism == HiddenMechanism::sensor_offset) hs.design.hidden_sensor_offset_n += e.magnitude;
    if (e.mechanism == HiddenMechanism::sensor_drift) hs.design.hidden_sensor_drift_nps += e.magnitude;
  }
  hs.design.seed = hs.draw.session_seed;
  hs.design.actuation_delay_cycles = hs.draw.actuation_delay_cycles;
  hs.design.session.session_id = "hidden-" + std::to_string(hidden_seed);
  hs.person = std::make_unique<HiddenEffectHuman>(person, effects, hs.draw, 1.0 / (fs * base.substeps));
  return hs;
}

}  // namespace manip::sim
