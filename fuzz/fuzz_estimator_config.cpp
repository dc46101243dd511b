// libFuzzer harness: bytes as config/estimator.yaml -> load_estimator_settings.
// A bad file must end in manip::ConfigError naming the file, never in a crash,
// a hang, another exception type or a leak.
// manip-fuzz-sources: src/estimation/*.cpp src/estimation/methods/*.cpp src/estimation/report/*.cpp src/dsp/*.cpp src/model/*.cpp src/schema/*.cpp src/common/*.cpp src/logging/*.cpp
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "manip/common/errors.hpp"
#include "manip/estimation/settings.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  // The loader reads a path (what the app gives it): one scratch file per process.
  static const std::string path = "/tmp/manip_fuzz_estimator_" + std::to_string(::getpid()) + ".yaml";
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (size && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  try {
    (void)manip::estimation::load_estimator_settings(path);
  } catch (const manip::ConfigError& e) {
    if (std::string(e.what()).rfind(path, 0) != 0) std::abort();  // the message names the file
  }
  return 0;
}
