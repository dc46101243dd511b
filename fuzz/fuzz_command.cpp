// libFuzzer harness: untrusted bytes on MANIP_COMMAND, through exactly what
// manip_rt's bus thread does with them (runtime::CommandGate::submit:
// logging::safe_decode -> validate_command -> the loop's command queue).
// Must never crash, throw, hang or leak; every input is either queued for the
// loop or answered with a status whose reason names the rejection.
// manip-fuzz-sources: src/runtime/bus.cpp src/runtime/config.cpp src/runtime/messages.cpp src/runtime/rt_thread.cpp src/runtime/timing.cpp src/control/*.cpp src/schema/*.cpp src/logging/*.cpp src/common/*.cpp src/model/*.cpp src/sim/*.cpp
#include <cstddef>
#include <cstdint>
#include <cstdlib>

#include "manip/command_t.hpp"
#include "manip/logging/safe_decode.hpp"
#include "manip/runtime/bus.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace manip::runtime;
  static const CommandLimits lim = CommandLimits::from_config(RtConfig{});
  CommandQueue q(4);
  CommandGate gate(q, lim);
  const auto st = gate.submit(data, static_cast<int>(size), 0, 2);
  if (st) {
    // Answered: never accepted, always with a reason.
    if (st->accepted || st->reason.empty()) std::abort();
  } else {
    // Queued for the loop: it must have decoded and passed validation.
    manip::control::Command c;
    if (!q.try_pop(c)) std::abort();
    if (c.kind < manip::command_t::START_SESSION || c.kind > manip::command_t::FAULT_RESET) std::abort();
    manip::command_t m;
    if (!manip::logging::safe_decode(data, size, m)) std::abort();
  }
  if (gate.received() != 1) std::abort();
  return 0;
}
