// One session description: round trip through session_t, and refusal of
// values nothing could be estimated from (field named).
#include <catch2/catch.hpp>

// GCC 12 reports -Wmaybe-uninitialized inside std::string's copy of a
// short-string-optimised member of a struct assigned field by field (GCC bug
// 105562 family, a false positive at -O3).
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif

#include <cmath>
#include <limits>

#include "manip/schema/codes.hpp"
#include "manip/schema/session_description.hpp"

using manip::schema::SessionDescription;

TEST_CASE("session description: every field survives the session message") {
  SessionDescription d;
  d.participant_id = "p7";
  d.session_id = "s3";
  d.source = "test";
  d.software_version = "9.9";
  d.utime_start_us = 123456789;
  d.sample_rate_hz = 2000;
  d.drive_rate_hz = 1000;
  d.m_adm_kg = {4.0, 6.0};
  d.d_adm_nspm = {12.0, 18.0};
  d.m_handle_kg = {0.31, 0.29};
  d.frame.origin_in_shoulder_m = {0.01, 0.41};
  d.frame.rot_rad = 0.1;
  d.anthropometrics.length_m[1] = 0.36;
  d.anthropometrics.inertia_kgm2[0] = 0.02;
  d.body_mass_kg = 71;
  d.body_height_m = 1.8;
  d.perturbation.duration_s = 0.2;
  d.perturbation.amplitude_n = 12;
  d.perturbation.trigger_x2_shoulder_m = 0.42;
  d.config_yaml = "x: 1\n";
  const SessionDescription e = manip::schema::from_message(manip::schema::to_message(d));
  CHECK(e.participant_id == "p7");
  CHECK(e.session_id == "s3");
  CHECK(e.source == "test");
  CHECK(e.software_version == "9.9");
  CHECK(e.utime_start_us == 123456789);
  CHECK(e.sample_rate_hz == 2000);
  CHECK(e.drive_rate_hz == 1000);
  CHECK(e.m_adm_kg == d.m_adm_kg);
  CHECK(e.d_adm_nspm == d.d_adm_nspm);
  CHECK(e.m_handle_kg == d.m_handle_kg);
  CHECK(e.frame.origin_in_shoulder_m == d.frame.origin_in_shoulder_m);
  CHECK(e.frame.rot_rad == 0.1);
  CHECK(e.anthropometrics.length_m[1] == 0.36);
  CHECK(e.anthropometrics.inertia_kgm2[0] == 0.02);
  CHECK(e.body_mass_kg == 71);
  CHECK(e.body_height_m == 1.8);
  CHECK(e.perturbation.duration_s == 0.2);
  CHECK(e.perturbation.amplitude_n == 12);
  CHECK(e.perturbation.trigger_x2_shoulder_m == 0.42);
  CHECK(e.config_yaml == "x: 1\n");
  CHECK(!e.invalid_reason());
  // Shoulder-frame inertia: R diag(m) R^T, computed by hand for 0.1 rad.
  const double c = std::cos(0.1), s = std::sin(0.1);
  CHECK(e.m_adm_shoulder_kg()(0, 0) == Approx(4.0 * c * c + 6.0 * s * s));
  CHECK(e.m_adm_shoulder_kg()(0, 1) == Approx((4.0 - 6.0) * c * s));
}

TEST_CASE("session description: unusable values are refused with the field named") {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  SessionDescription d;
  CHECK(!d.invalid_reason());
  d.m_adm_kg[1] = nan;
  REQUIRE(d.invalid_reason());
  CHECK(d.invalid_reason()->rfind("m_adm_kg[1]:", 0) == 0);
  d = SessionDescription{};
  d.m_handle_kg[0] = -0.1;
  CHECK(d.invalid_reason()->rfind("m_handle_kg[0]:", 0) == 0);
  d = SessionDescription{};
  d.sample_rate_hz = 1e9;
  CHECK(d.invalid_reason()->rfind("sample_rate_hz:", 0) == 0);
  d = SessionDescription{};
  d.anthropometrics.mass_kg[0] = 0;
  CHECK(d.invalid_reason()->find("mass_kg") != std::string::npos);
}

TEST_CASE("schema codes: the C++ names carry the .lcm constants") {
  using manip::state_t;
  namespace schema = manip::schema;
  // Values as documented in docs/schema-controller.md (the contract for clients).
  CHECK(static_cast<int>(schema::Mode::kRunning) == 2);
  CHECK(state_t::MODE_RUNNING == 2);
  CHECK(static_cast<int>(schema::Phase::kReach) == 2);
  CHECK(state_t::PHASE_RETURN == 1);
  CHECK(schema::fault::kLogger == (1u << 13));
  CHECK(schema::fault::kWorkspace == 1u);
}
