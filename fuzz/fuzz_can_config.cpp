// libFuzzer harness: bytes as a CANopen bus file (ros2_canopen bus.yml style)
// -> canopen::parse_config. Refusal is a false return with "file:line: key:
// reason" lines, never a crash, a hang, an exception or a leak.
// manip-fuzz-sources: src/canopen/*.cpp src/common/*.cpp
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "manip/canopen/config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  manip::canopen::CanConfig cfg;
  std::vector<std::string> errors;
  const bool ok = manip::canopen::parse_config(text, "fuzz.yml", cfg, errors);
  if (!ok) {
    if (errors.empty()) std::abort();  // a refusal always says why
    for (const auto& e : errors)
      if (e.rfind("fuzz.yml", 0) != 0) std::abort();  // and names the file
  }
  return 0;
}
