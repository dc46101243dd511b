#include "manip/runtime/backends.hpp"

#include "manip/hardware/can_backend.hpp"
#include "manip/hardware/sim_backend.hpp"

namespace manip::runtime {

std::unique_ptr<hardware::Backend> make_backend(const std::string& name, const RtConfig& cfg) {
  if (name == "sim") {
    try {
      return std::make_unique<hardware::SimBackend>(cfg, cfg.sim, hardware::make_sim_human(cfg, cfg.sim));
    } catch (const Error&) {
      throw;
    } catch (const std::exception& e) {  // e.g. the neuromech arm's YAML
      throw ConfigError(std::string("sim backend: ") + e.what());
    }
  }
  if (name == "can") return std::make_unique<hardware::CanBackend>(cfg, cfg.sim, hardware::load_can_config("config/can.yaml"));
  throw UsageError("unknown backend '" + name + "' (choose sim or can)");
}

}  // namespace manip::runtime
