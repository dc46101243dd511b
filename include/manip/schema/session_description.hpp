#pragma once
// The one description of a session: everything an offline tool needs to
// interpret the 4 kHz state stream (admittance of eq. 20, handle mass of
// eq. 19, frame offset, anthropometrics for M_BSP of eq. 16, perturbation
// design of eq. 22-23). manip_rt's configuration, the simulator and the
// estimator all hold this struct, and it travels as session_t (first message
// of every log, lcmtypes/session_t.lcm). Defaults are the paper's apparatus
// (§5.1) and the sources cited in config/rt.yaml; there is no other copy.
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>

#include "manip/common/frames.hpp"
#include "manip/common/types.hpp"
#include "manip/model/arm.hpp"
#include "manip/session_t.hpp"

namespace manip::schema {

struct PerturbationDesign {
  double duration_s{0.15};             // T_pert (paper §3.2)
  double amplitude_n{15.0};            // A_pert (paper §3.2)
  double trigger_x2_shoulder_m{0.40};  // onset when the hand first crosses this x2 moving to the goal
};

struct SessionDescription {
  int schema_version{manip::session_t::SCHEMA_VERSION};
  std::string software_version;
  std::string source;  // "manip_rt/sim", "manip_rt/can", "manip_sim", ...
  std::int64_t utime_start_us{0};
  std::string participant_id;
  std::string session_id;

  double sample_rate_hz{4000.0};  // paper §5.1
  double drive_rate_hz{2000.0};   // paper §5.1: drive commands downsampled to 2 kHz

  // Diagonal per workspace axis (eq. 20, paper §5.1).
  Vec2 m_adm_kg{5.0, 5.0};
  Vec2 d_adm_nspm{15.0, 15.0};
  // Handle between the force sensor and the hand (eq. 19): aluminium handle
  // and grip above the sensor's measuring flange (config/rt.yaml rationale).
  Vec2 m_handle_kg{0.25, 0.25};

  WorkspaceToShoulder frame{};
  Anthropometrics anthropometrics{};
  double body_mass_kg{0.0};   // 0 = unknown
  double body_height_m{0.0};  // 0 = unknown

  PerturbationDesign perturbation{};
  std::string config_yaml;  // complete effective configuration text

  // The admittance and handle inertia in the shoulder frame (the estimator's
  // frame): R diag(m) R^T; identity rotation for the usual pure translation.
  [[nodiscard]] Mat2 m_adm_shoulder_kg() const;
  [[nodiscard]] Mat2 d_adm_shoulder_nspm() const;
  [[nodiscard]] Mat2 m_handle_shoulder_kg() const;

  // Empty when the description can be used, else "field: reason (got v)" for
  // the first bad field: non-finite or out-of-range values (a NaN M_adm or an
  // absurd sample rate must be refused, never estimated).
  [[nodiscard]] std::optional<std::string> invalid_reason() const;
};

manip::session_t to_message(const SessionDescription& d);
// A faithful copy; call invalid_reason() before using it.
SessionDescription from_message(const manip::session_t& m);

}  // namespace manip::schema
