#pragma once
// The one way to build a simulated person (manip_sim, the sim backend of
// manip_rt, studies, tests): a registry of human models keyed by name, each a
// builder from one parameter struct. The struct is plain data (no control or
// runtime config types), so every caller fills it from its own configuration.
//
// Adding a human model: one new file that defines the model and its builder,
// plus one registration line, either in kBuiltins (human_factory.cpp) for a
// model shipped in the library, or a static
//   const bool registered = sim::register_human_model({"toy", "...", &build_toy});
// in the file itself (tests/sim/test_human_factory.cpp does this).
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "manip/model/arm.hpp"
#include "manip/sim/human.hpp"
#include "manip/sim/linear_human.hpp"

namespace manip::sim {

struct HumanSpec {
  std::string model{"linear"};  // registry key: linear | neuromech | any registered name
  double sample_rate_hz{4000.0};  // the session's sample rate (state_t stream)
  // The plant step the caller will use [s]; 0 = the model chooses (the
  // returned BuiltHuman::step_s): the linear person 4 substeps per sample,
  // the neuromechanical arm its integration.session_step_s with the midpoint
  // plant step (manip_sim). Non-zero (manip_rt's sim backend: 1/(f_s substeps))
  // must be a whole multiple of the model's own integration step.
  double plant_step_s{0.0};

  // linear: the endpoint impedance person (sample_rate_hz is set from the step).
  LinearHumanParams linear{};

  // neuromech: parameters file (config/arm_model.yaml format; "" = the
  // built-in defaults, which equal config/arm_model.yaml) and which feedback
  // pathways run: config (as in the file) | intrinsic (all off: the
  // ground-truth case) | short-latency (only the short-latency reflex on).
  std::string arm_config;
  std::string feedback{"config"};
};

struct BuiltHuman {
  std::unique_ptr<HumanModel> model;
  double step_s{0.0};            // plant step to use [s] (the spec's, or the model's choice)
  bool midpoint_plant{false};    // step_ideal_admittance(..., midpoint)
  std::optional<Anthropometrics> anthropometrics;  // the simulated arm's (session message M_BSP), if it has one
  std::string config_yaml;       // effective parameters for session_t.config_yaml ("" = none)
};

using HumanBuilder = BuiltHuman (*)(const HumanSpec&);

struct HumanRegistration {
  std::string name;
  std::string description;  // one line for --help
  HumanBuilder build{nullptr};
};

// Registers a model; returns true (for static registration). A name already
// registered is refused (std::logic_error): two models must not share a name.
bool register_human_model(const HumanRegistration& r);

// Builds spec.model. manip::UsageError for an unknown name or a bad choice,
// manip::ConfigError for a bad parameters file or a plant step the model cannot run.
BuiltHuman make_human(const HumanSpec& spec);

// Registered models, built-ins first, then in registration order.
std::vector<HumanRegistration> human_models();

}  // namespace manip::sim
