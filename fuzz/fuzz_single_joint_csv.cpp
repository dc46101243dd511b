// libFuzzer harness: bytes as a single-joint CSV record (diagnose_model
// --single-joint) -> read_single_joint_csv. A bad file must end in
// manip::InputError whose message starts with the file name, never in a crash,
// a hang, another exception type or a leak; a file it accepts has equally many
// position and torque samples and a positive, finite sample period.
// manip-fuzz-sources: src/diagnosis/single_joint.cpp src/diagnosis/engine.cpp src/diagnosis/stats.cpp src/diagnosis/mechanisms.cpp src/diagnosis/report.cpp src/diagnosis/traces.cpp src/dsp/*.cpp src/common/*.cpp
#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "manip/common/errors.hpp"
#include "manip/diagnosis/single_joint.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string path = "/tmp/manip_fuzz_single_joint_" + std::to_string(::getpid()) + ".csv";
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (size && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  try {
    const auto rec = manip::diagnosis::read_single_joint_csv(path);
    if (rec.pos_rad.size() != rec.torque_nm.size() || rec.pos_rad.size() < 2) std::abort();
    if (!(rec.dt_s > 0.0) || !std::isfinite(rec.dt_s)) std::abort();
  } catch (const manip::InputError& e) {
    if (std::string(e.what()).rfind(path, 0) != 0) std::abort();  // the message names the file
  }
  return 0;
}
