#pragma once
// Parameters of the simulation backend (rt.yaml `sim:`): the simulated stages
// and drive, the simulated person's arm (sim.human) and behaviour
// (sim.participant). Read by runtime::load_rt_config; defaults equal the
// shipped config/rt.yaml.
#include <cstdint>
#include <string>

#include "manip/common/types.hpp"

namespace manip::hardware {

struct SimHumanConfig {
  std::string model{"linear"};                      // linear | neuromech
  std::string arm_config{"config/arm_model.yaml"};  // neuromech parameters (relative to the working directory)
  Mat2 m_kg{(Mat2() << 1.515460, -0.824986, -0.824986, 1.409055).finished()};
  Mat2 d_nspm{(Mat2() << 10.98, -7.94, -8.54, 6.75).finished()};
  Mat2 k_npm{(Mat2() << 110.52, -106.05, -106.05, 313.75).finished()};
  Mat2 m_load_kg{Mat2::Identity() * 5.25};
  Mat2 d_load_nspm{Mat2::Identity() * 15.0};
  double voluntary_delay_s{0.160};
  // rt.yaml's values: 300/30 makes the delayed loop on M_adm = 5 kg unstable
  // within seconds of holding (the rationale is in the file).
  Mat2 k_voluntary_npm{Mat2::Identity() * 100.0};
  Mat2 d_voluntary_nspm{Mat2::Identity() * 20.0};
  double motor_noise_n{0.0};
  double motor_noise_tau_s{0.05};
  bool operator==(const SimHumanConfig&) const = default;
};

struct SimParticipantConfig {
  double reaction_time_s{0.25};
  double reaction_time_jitter_s{0.05};
  double reach_duration_s{3.0};
  double reach_duration_jitter_s{0.25};
  double return_duration_s{1.2};
  double lateral_bow_std_m{0.003};
  bool operator==(const SimParticipantConfig&) const = default;
};

struct SimConfig {
  Vec2 stage_mass_kg{12.0, 4.0};
  Vec2 viscous_nspm{20.0, 10.0};
  Vec2 coulomb_n{4.0, 2.0};
  double coulomb_velocity_mps{0.001};
  double encoder_resolution_m{1e-6};
  double force_noise_n{0.0};
  double drive_peak_force_n{400.0};
  int substeps{4};
  std::uint64_t seed{1};
  SimHumanConfig human{};
  SimParticipantConfig participant{};
  bool operator==(const SimConfig&) const = default;
};

}  // namespace manip::hardware
