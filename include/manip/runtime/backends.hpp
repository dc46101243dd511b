#pragma once
// The backends manip_rt can run (--backend): "sim" (the simulated stages and
// participant), "can" (CANopen CiA 402 drives; refused until its issue lands).
#include <memory>
#include <string>

#include "manip/hardware/backend.hpp"
#include "manip/runtime/config.hpp"

namespace manip::runtime {

// Throws UsageError (unknown name), ConfigError (e.g. the neuromech arm's
// YAML) or hardware::BackendError (not available). The backend is returned
// Unconfigured: run_session configures and enables it.
std::unique_ptr<hardware::Backend> make_backend(const std::string& name, const RtConfig& cfg);

}  // namespace manip::runtime
