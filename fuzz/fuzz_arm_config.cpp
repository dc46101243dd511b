// libFuzzer harness: bytes as config/arm_model.yaml -> load_neuromech_params.
// A bad file must end in manip::ConfigError naming the file, never in a crash,
// a hang, another exception type or a leak.
// manip-fuzz-sources: src/sim/*.cpp src/control/*.cpp src/model/*.cpp src/schema/*.cpp src/common/*.cpp src/logging/*.cpp
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "manip/common/errors.hpp"
#include "manip/sim/neuromech_arm.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path = "/tmp/manip_fuzz_arm_" + std::to_string(::getpid()) + ".yaml";
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (size && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  try {
    (void)manip::sim::load_neuromech_params(path);
  } catch (const manip::ConfigError& e) {
    if (std::string(e.what()).rfind(path, 0) != 0) std::abort();
  }
  return 0;
}
