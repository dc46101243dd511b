#include "manip/hardware/backend.hpp"

namespace manip::hardware {

const char* state_name(BackendState s) {
  switch (s) {
    case BackendState::kUnconfigured: return "unconfigured";
    case BackendState::kInactive: return "inactive (configured, drives disabled)";
    case BackendState::kActive: return "active (drives enabled)";
    case BackendState::kFinalized: return "finalized";
  }
  return "?";
}

void Backend::require(BackendState s, const char* call) const {
  if (state_ != s)
    throw BackendStateError("backend '" + name() + "': " + call + " refused in state " + state_name(state_) +
                            " (needs " + state_name(s) + ")");
}

void Backend::configure() {
  require(BackendState::kUnconfigured, "configure()");
  on_configure();
  state_ = BackendState::kInactive;
}

void Backend::enable() {
  require(BackendState::kInactive, "enable()");
  on_enable();
  state_ = BackendState::kActive;
}

void Backend::disable() noexcept {
  if (state_ != BackendState::kActive) return;
  on_disable();
  state_ = BackendState::kInactive;
}

void Backend::shutdown() noexcept {
  if (state_ == BackendState::kFinalized) return;
  disable();
  if (state_ == BackendState::kInactive) on_shutdown();
  state_ = BackendState::kFinalized;
}

}  // namespace manip::hardware
