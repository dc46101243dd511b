#include "manip/sim/human_factory.hpp"

#include <cmath>
#include <mutex>
#include <stdexcept>

#include "manip/common/errors.hpp"
#include "manip/sim/neuromech_arm.hpp"

namespace manip::sim {
namespace {

BuiltHuman build_linear(const HumanSpec& s) {
  BuiltHuman b;
  // 4 substeps per sample: semi-implicit Euler at 16 kHz (docs/simulation.md).
  b.step_s = s.plant_step_s > 0.0 ? s.plant_step_s : 1.0 / (4.0 * s.sample_rate_hz);
  LinearHumanParams p = s.linear;
  p.sample_rate_hz = 1.0 / b.step_s;  // advance() runs once per plant step (delay line)
  b.model = std::make_unique<LinearImpedanceHuman>(p);
  return b;
}

BuiltHuman build_neuromech(const HumanSpec& s) {
  NeuromechParams np = s.arm_config.empty() ? NeuromechParams{} : load_neuromech_params(s.arm_config);
  if (s.feedback == "intrinsic") {
    np.disable_feedback();
  } else if (s.feedback == "short-latency") {
    np.disable_feedback();
    np.pathway(Pathway::kShortLatency).enabled = true;
  } else if (s.feedback != "config") {
    throw UsageError("feedback must be config, intrinsic or short-latency (got '" + s.feedback + "')");
  }
  const std::string where = s.arm_config.empty() ? std::string("built-in arm parameters") : s.arm_config;
  BuiltHuman b;
  if (s.plant_step_s > 0.0) {
    // advance() would reject a plant step that is not a whole multiple of the
    // arm's step at the first cycle: refuse it here, at start-up.
    const double ratio = s.plant_step_s / np.step_s;
    if (std::abs(ratio - std::round(ratio)) > 1e-6 * ratio || std::round(ratio) < 1.0)
      throw ConfigError(where + ": integration.step_s " + std::to_string(np.step_s) +
                        " s does not divide the plant step " + std::to_string(s.plant_step_s) + " s");
    b.step_s = s.plant_step_s;
  } else {
    // One arm step per session sample with the second-order plant step
    // (integration.session_step_s; integration.step_s is manip_rt's sub-stepped rate).
    np.step_s = np.session_step_s;
    b.step_s = np.step_s;
    b.midpoint_plant = true;
  }
  if (auto why = np.invalid_reason()) throw ConfigError(where + ": " + *why);
  b.anthropometrics = np.anthropometrics;  // the session message must describe the simulated arm (M_BSP)
  b.config_yaml = neuromech_params_to_yaml(np);
  b.model = std::make_unique<NeuromechanicalArm>(np);
  return b;
}

struct Registry {
  std::mutex mutex;
  std::vector<HumanRegistration> models;
};

// Built on first use, so a model registered from another file's static
// initialiser finds the built-ins already there (no initialisation-order issue).
Registry& registry() {
  static Registry r{{},
                    {
                        // The models shipped in the library: one line each.
                        {"linear", "linear endpoint impedance around a minimum-jerk plan (linear_human.hpp)", &build_linear},
                        {"neuromech", "two-link six-muscle arm with delayed reflexes, paper §4.1 (neuromech_arm.hpp)",
                         &build_neuromech},
                    }};
  return r;
}

}  // namespace

bool register_human_model(const HumanRegistration& r) {
  auto& reg = registry();
  const std::lock_guard lock(reg.mutex);
  if (r.name.empty() || r.build == nullptr) throw std::logic_error("register_human_model: empty name or builder");
  for (const auto& m : reg.models)
    if (m.name == r.name) throw std::logic_error("register_human_model: '" + r.name + "' is already registered");
  reg.models.push_back(r);
  return true;
}

std::vector<HumanRegistration> human_models() {
  auto& reg = registry();
  const std::lock_guard lock(reg.mutex);
  return reg.models;
}

BuiltHuman make_human(const HumanSpec& spec) {
  if (!(spec.sample_rate_hz > 0.0) || !std::isfinite(spec.sample_rate_hz) || !(spec.plant_step_s >= 0.0))
    throw UsageError("human model: sample rate must be positive and the plant step non-negative");
  HumanBuilder build = nullptr;
  std::string names;
  for (const auto& m : human_models()) {
    if (m.name == spec.model) build = m.build;
    names += (names.empty() ? "" : ", ") + m.name;
  }
  if (!build) throw UsageError("unknown human model '" + spec.model + "' (registered: " + names + ")");
  BuiltHuman b = build(spec);
  if (!b.model || !(b.step_s > 0.0)) throw std::logic_error("human model '" + spec.model + "': builder returned no model or step");
  return b;
}

}  // namespace manip::sim
