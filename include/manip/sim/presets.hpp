#pragma once
// Named simulation presets shared by manip_sim, the accuracy study and tests,
// so "realistic noise" means the same numbers everywhere (docs/accuracy-study.md).
#include <string>

#include "manip/sim/linear_human.hpp"
#include "manip/sim/session_runner.hpp"

namespace manip::sim {

// quantisation / motor / variability: one source of `realistic` alone (for
// attributing the error of the accuracy study to its cause).
enum class NoiseLevel { none, quantisation, motor, variability, realistic };

// Sensor and movement variability of a lab session:
//   none:      no quantisation, no noise, identical 3 s reaches
//   realistic: 1 µm encoder quantisation (§5.1), force-sensor noise 0.05 N std,
//              motor noise 0.2 N std (Ornstein-Uhlenbeck, 50 ms), reach durations
//              3 ± 0.25 s (uniform), lateral path bow 5 mm std.
void apply_noise(NoiseLevel level, SessionDesign& d, LinearHumanParams& h);
NoiseLevel parse_noise_level(const std::string& s);  // throws std::invalid_argument

// The two synthetic people of the accuracy study.
LinearHumanParams table1_person();   // paper Table 1 means (K symmetrised), M = M_BSP at the trigger point
LinearHumanParams stiff_person();    // about twice as stiff and damped

}  // namespace manip::sim
