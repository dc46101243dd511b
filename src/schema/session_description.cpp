#include "manip/schema/session_description.hpp"

#include <cmath>
#include <sstream>

namespace manip::schema {
namespace {

Mat2 to_shoulder(const WorkspaceToShoulder& f, const Vec2& diag) {
  const Mat2 r = f.rotation();
  return r * Mat2(diag.asDiagonal()) * r.transpose();
}

std::string bad(const std::string& field, const std::string& rule, double v) {
  std::ostringstream os;
  os << field << ": " << rule << " (got " << v << ")";
  return os.str();
}

}  // namespace

Mat2 SessionDescription::m_adm_shoulder_kg() const { return to_shoulder(frame, m_adm_kg); }
Mat2 SessionDescription::d_adm_shoulder_nspm() const { return to_shoulder(frame, d_adm_nspm); }
Mat2 SessionDescription::m_handle_shoulder_kg() const { return to_shoulder(frame, m_handle_kg); }

std::optional<std::string> SessionDescription::invalid_reason() const {
  // Bounds are plausibility limits of a manipulandum, not tuning: a log outside
  // them was written wrongly and nothing estimated from it would mean anything.
  if (!std::isfinite(sample_rate_hz) || sample_rate_hz < 100.0 || sample_rate_hz > 100000.0)
    return bad("sample_rate_hz", "must be in [100, 100000] Hz", sample_rate_hz);
  if (!std::isfinite(drive_rate_hz) || drive_rate_hz <= 0.0 || drive_rate_hz > sample_rate_hz)
    return bad("drive_rate_hz", "must be in (0, sample_rate_hz]", drive_rate_hz);
  for (int i = 0; i < 2; ++i) {
    const std::string ix = "[" + std::to_string(i) + "]";
    if (!std::isfinite(m_adm_kg[i]) || m_adm_kg[i] <= 0.0 || m_adm_kg[i] > 1000.0)
      return bad("m_adm_kg" + ix, "must be in (0, 1000] kg", m_adm_kg[i]);
    if (!std::isfinite(d_adm_nspm[i]) || d_adm_nspm[i] < 0.0 || d_adm_nspm[i] > 10000.0)
      return bad("d_adm_nspm" + ix, "must be in [0, 10000] N s/m", d_adm_nspm[i]);
    if (!std::isfinite(m_handle_kg[i]) || m_handle_kg[i] < 0.0 || m_handle_kg[i] > 100.0)
      return bad("m_handle_kg" + ix, "must be in [0, 100] kg", m_handle_kg[i]);
    if (!std::isfinite(frame.origin_in_shoulder_m[i]) || std::abs(frame.origin_in_shoulder_m[i]) > 10.0)
      return bad("workspace_origin_in_shoulder_m" + ix, "must be finite, |v| <= 10 m", frame.origin_in_shoulder_m[i]);
  }
  if (!std::isfinite(frame.rot_rad) || std::abs(frame.rot_rad) > 7.0)
    return bad("workspace_to_shoulder_rot_rad", "must be finite, |v| <= 7 rad", frame.rot_rad);
  if (auto why = anthropometrics.invalid_reason()) return "segment " + *why;
  if (!std::isfinite(body_mass_kg) || body_mass_kg < 0.0) return bad("body_mass_kg", "must be >= 0", body_mass_kg);
  if (!std::isfinite(body_height_m) || body_height_m < 0.0) return bad("body_height_m", "must be >= 0", body_height_m);
  if (!std::isfinite(perturbation.duration_s) || perturbation.duration_s <= 0.0 || perturbation.duration_s > 10.0)
    return bad("pert_duration_s", "must be in (0, 10] s", perturbation.duration_s);
  if (!std::isfinite(perturbation.amplitude_n) || perturbation.amplitude_n < 0.0 || perturbation.amplitude_n > 1000.0)
    return bad("pert_amplitude_n", "must be in [0, 1000] N", perturbation.amplitude_n);
  if (!std::isfinite(perturbation.trigger_x2_shoulder_m) || std::abs(perturbation.trigger_x2_shoulder_m) > 10.0)
    return bad("trigger_x2_shoulder_m", "must be finite, |v| <= 10 m", perturbation.trigger_x2_shoulder_m);
  return std::nullopt;
}

manip::session_t to_message(const SessionDescription& d) {
  manip::session_t s{};
  s.schema_version = d.schema_version;
  s.software_version = d.software_version;
  s.source = d.source;
  s.utime_start = d.utime_start_us;
  s.participant_id = d.participant_id;
  s.session_id = d.session_id;
  s.sample_rate_hz = d.sample_rate_hz;
  s.drive_rate_hz = d.drive_rate_hz;
  for (int i = 0; i < 2; ++i) {
    s.m_adm_kg[i] = d.m_adm_kg[i];
    s.d_adm_nspm[i] = d.d_adm_nspm[i];
    s.m_handle_kg[i] = d.m_handle_kg[i];
    s.workspace_origin_in_shoulder_m[i] = d.frame.origin_in_shoulder_m[i];
    s.segment_length_m[i] = d.anthropometrics.length_m[i];
    s.segment_mass_kg[i] = d.anthropometrics.mass_kg[i];
    s.segment_com_m[i] = d.anthropometrics.com_m[i];
    s.segment_inertia_kgm2[i] = d.anthropometrics.inertia_kgm2[i];
  }
  s.workspace_to_shoulder_rot_rad = d.frame.rot_rad;
  s.body_mass_kg = d.body_mass_kg;
  s.body_height_m = d.body_height_m;
  s.pert_duration_s = d.perturbation.duration_s;
  s.pert_amplitude_n = d.perturbation.amplitude_n;
  s.trigger_x2_shoulder_m = d.perturbation.trigger_x2_shoulder_m;
  s.config_yaml = d.config_yaml;
  return s;
}

SessionDescription from_message(const manip::session_t& m) {
  SessionDescription d;
  d.schema_version = m.schema_version;
  d.software_version = m.software_version;
  d.source = m.source;
  d.utime_start_us = m.utime_start;
  d.participant_id = m.participant_id;
  d.session_id = m.session_id;
  d.sample_rate_hz = m.sample_rate_hz;
  d.drive_rate_hz = m.drive_rate_hz;
  for (int i = 0; i < 2; ++i) {
    d.m_adm_kg[i] = m.m_adm_kg[i];
    d.d_adm_nspm[i] = m.d_adm_nspm[i];
    d.m_handle_kg[i] = m.m_handle_kg[i];
    d.frame.origin_in_shoulder_m[i] = m.workspace_origin_in_shoulder_m[i];
    d.anthropometrics.length_m[i] = m.segment_length_m[i];
    d.anthropometrics.mass_kg[i] = m.segment_mass_kg[i];
    d.anthropometrics.com_m[i] = m.segment_com_m[i];
    d.anthropometrics.inertia_kgm2[i] = m.segment_inertia_kgm2[i];
  }
  d.frame.rot_rad = m.workspace_to_shoulder_rot_rad;
  d.body_mass_kg = m.body_mass_kg;
  d.body_height_m = m.body_height_m;
  d.perturbation.duration_s = m.pert_duration_s;
  d.perturbation.amplitude_n = m.pert_amplitude_n;
  d.perturbation.trigger_x2_shoulder_m = m.trigger_x2_shoulder_m;
  d.config_yaml = m.config_yaml;
  return d;
}

}  // namespace manip::schema
