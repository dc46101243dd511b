#include "manip/hardware/backend.hpp"

#include "manip/hardware/sim_backend.hpp"

namespace manip::hardware {

BackendResult make_backend(const std::string& name, const control::RtConfig& cfg) {
  BackendResult r;
  if (name == "sim") {
    try {
      r.backend = std::make_unique<SimBackend>(cfg, make_sim_human(cfg));
    } catch (const std::exception& e) {  // e.g. the neuromech arm's YAML
      r.exit_code = exit_code::kConfig;
      r.error = std::string("sim backend: ") + e.what();
    }
    return r;
  }
  if (name == "can") {
    r.exit_code = exit_code::kBackendUnavailable;
    r.error =
        "backend 'can' (CANopen CiA 402 drives over SocketCAN) is not implemented yet (a later issue); "
        "refusing to start. Use --backend sim.";
    return r;
  }
  r.exit_code = exit_code::kUsage;
  r.error = "unknown backend '" + name + "' (choose sim or can)";
  return r;
}

}  // namespace manip::hardware
