// libFuzzer harness: bytes as rt.yaml text -> runtime::parse_rt_config. A bad
// file must end in manip::ConfigError (exit 3, "file:line: key: reason"),
// never in a crash, a hang, another exception type or a leak.
// manip-fuzz-sources: src/runtime/config.cpp src/control/*.cpp src/schema/*.cpp src/common/*.cpp src/model/*.cpp src/sim/*.cpp
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "manip/common/errors.hpp"
#include "manip/runtime/config.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    const manip::runtime::RtConfig c = manip::runtime::parse_rt_config(text, "fuzz.yaml");
    // Accepted: the loader's own promise (a valid session description).
    if (c.session.invalid_reason()) std::abort();
  } catch (const manip::ConfigError& e) {
    if (std::string(e.what()).rfind("fuzz.yaml", 0) != 0) std::abort();  // the message names the file
  }
  // Any other exception escapes and libFuzzer reports it as a crash.
  return 0;
}
