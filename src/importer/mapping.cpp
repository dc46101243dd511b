#include "manip/importer/mapping.hpp"

#include <cmath>
#include <numbers>
#include <utility>

#include "manip/common/errors.hpp"
#include "manip/common/yaml_reader.hpp"

namespace manip::importer {

std::string Where::str() const {
  std::string s = file;
  if (line > 0) s += ":" + std::to_string(line);
  return s + ": " + key;
}

namespace {

using manip::yaml::Section;

Where where_of(const Section& s, const std::string& key) {
  Where w;
  w.file = s.file();
  w.key = s.full(key);
  const YAML::Node n = s.node()[key];
  const YAML::Mark m = n.IsDefined() ? n.Mark() : s.node().Mark();
  w.line = m.line >= 0 ? m.line + 1 : 0;
  return w;
}

// SI factor of a unit name; the lists are the whole of what is accepted.
const std::vector<std::pair<std::string, double>> kLength{{"m", 1.0}, {"cm", 1e-2}, {"mm", 1e-3}, {"um", 1e-6}};
const std::vector<std::pair<std::string, double>> kForce{{"N", 1.0}, {"mN", 1e-3}, {"kN", 1e3}};
const std::vector<std::pair<std::string, double>> kTime{{"s", 1.0}, {"ms", 1e-3}, {"us", 1e-6}};
const std::vector<std::pair<std::string, double>> kAngle{{"rad", 1.0}, {"deg", std::numbers::pi / 180.0}};

double unit_factor(Section& s, const std::string& key, const std::vector<std::pair<std::string, double>>& table,
                   const char* what, std::string& name_out) {
  std::vector<std::string> names;
  for (const auto& [n, f] : table) names.push_back(n);
  const YAML::Node n = s.get(key);
  if (!n.IsScalar()) s.fail(key, std::string("expected a unit of ") + what);
  name_out = n.Scalar();
  for (const auto& [u, f] : table)
    if (u == name_out) return f;
  std::string list;
  for (const auto& u : names) list += (list.empty() ? "" : ", ") + u;
  s.fail(key, "unknown unit '" + name_out + "' for " + what + " (known: " + list + ")");
}

std::string variable_name(Section& s, const std::string& key) {
  const std::string v = s.string(key);
  return v;
}

SignalSpec read_signal(Section& parent, const std::string& key, const std::vector<std::pair<std::string, double>>& units,
                       const char* what) {
  SignalSpec sp;
  sp.where = where_of(parent, key);
  Section s = parent.sub(key);
  const bool one = s.has("variable"), two = s.has("variables");
  if (one == two) s.fail(one ? "variables" : "variable", "give exactly one of `variable` (an N x k matrix) or "
                                                         "`variables` (two vectors, one per component)");
  if (one) {
    sp.variables.push_back(variable_name(s, "variable"));
    if (s.has("columns")) {
      const YAML::Node c = s.get("columns");
      if (!c.IsSequence() || c.size() != 2) s.fail("columns", "expected two 1-based column numbers, e.g. [1, 2]");
      for (int i = 0; i < 2; ++i) {
        int v{};
        if (!c[i].IsScalar() || !YAML::convert<int>::decode(c[i], v) || v < 1)
          s.fail("columns", "element " + std::to_string(i) + " is not a column number >= 1 ('" +
                                yaml::scalar_text(c[i]) + "')");
        sp.columns[static_cast<std::size_t>(i)] = v;
      }
    }
  } else {
    const YAML::Node v = s.get("variables");
    if (!v.IsSequence() || v.size() != 2) s.fail("variables", "expected two variable names [component 1, component 2]");
    for (int i = 0; i < 2; ++i) {
      if (!v[i].IsScalar() || v[i].Scalar().empty())
        s.fail("variables", "element " + std::to_string(i) + " is not a variable name");
      sp.variables.push_back(v[i].Scalar());
    }
  }
  sp.to_si = unit_factor(s, "unit", units, what, sp.unit);
  s.finish();
  return sp;
}

MarkerSpec read_marker(Section& parent, const std::string& key) {
  MarkerSpec m;
  m.where = where_of(parent, key);
  Section s = parent.sub(key);
  m.variable = variable_name(s, "variable");
  if (s.has("as")) {
    const auto as = s.choice("as", {"flag", "index", "time"});
    m.as = as == "flag" ? MarkerSpec::As::kFlag : as == "index" ? MarkerSpec::As::kIndex : MarkerSpec::As::kTime;
  }
  s.finish();
  return m;
}

}  // namespace

Mapping parse_mapping(const std::string& text, const std::string& file) {
  const YAML::Node root = yaml::parse(text, file);
  Section top(file, root, "");
  Mapping m;
  m.file = file;
  m.text = text;

  {  // time
    m.time_where = where_of(top, "time");
    Section t = top.sub("time");
    const bool var = t.has("variable"), rate = t.has("sample_rate_hz");
    if (var == rate)
      t.fail(var ? "sample_rate_hz" : "variable",
             "give exactly one of `variable` (the time of each sample) or `sample_rate_hz` (samples equally spaced)");
    if (var) {
      m.time_variable = variable_name(t, "variable");
      std::string u;
      m.time_to_s = unit_factor(t, "unit", kTime, "time", u);
      if (t.has("max_jitter"))
        m.max_jitter = t.number("max_jitter", [](double v) { return v > 0 && v < 0.5; }, "must be in (0, 0.5)");
    } else {
      m.sample_rate_hz = t.positive("sample_rate_hz");
    }
    t.finish();
  }
  {  // signals
    Section s = top.sub("signals");
    m.position = read_signal(s, "position", kLength, "a length");
    m.handle_force = read_signal(s, "handle_force", kForce, "a force");
    m.perturbation_force = read_signal(s, "perturbation_force", kForce, "a force");
    s.finish();
  }
  {  // frame
    Section f = top.sub("frame");
    m.axes_where = where_of(f, "axes");
    if (f.has("axes")) {
      const YAML::Node a = f.get("axes");
      if (!a.IsSequence() || a.size() != 2) f.fail("axes", "expected two signed component numbers, e.g. [1, 2] or [-2, 1]");
      for (int i = 0; i < 2; ++i) {
        int v{};
        if (!a[i].IsScalar() || !YAML::convert<int>::decode(a[i], v) || (std::abs(v) != 1 && std::abs(v) != 2))
          f.fail("axes", "element " + std::to_string(i) + " must be 1, 2, -1 or -2 (got '" + yaml::scalar_text(a[i]) + "')");
        m.axes[static_cast<std::size_t>(i)] = v;
      }
      if (std::abs(m.axes[0]) == std::abs(m.axes[1]))
        f.fail("axes", "the two workspace axes must come from different recorded components");
    }
    m.frame.origin_in_shoulder_m = f.vec2("origin_in_shoulder_m");
    m.frame.rot_rad = f.has("rotation_deg") ? f.any_number("rotation_deg") * std::numbers::pi / 180.0 : 0.0;
    f.finish();
  }
  {  // trials
    Section t = top.sub("trials");
    const bool idx = t.has("index"), st = t.has("start"), en = t.has("end");
    if (idx && (st || en)) t.fail("index", "give either `index` or `start` + `end` markers, not both");
    if (!idx && !(st && en))
      t.fail(st ? "end" : "start", "missing: trials need `index` (a trial-index variable) or both `start` and `end`");
    if (idx) {
      m.trial_mode = Mapping::TrialMode::kIndex;
      m.index_where = where_of(t, "index");
      Section i = t.sub("index");
      m.index_variable = variable_name(i, "variable");
      if (i.has("outside")) m.index_outside = i.any_number("outside");
      if (i.has("first")) m.index_first = i.integer("first", -1000000, 1000000);
      i.finish();
    } else {
      m.trial_mode = Mapping::TrialMode::kMarkers;
      m.start = read_marker(t, "start");
      m.end = read_marker(t, "end");
    }
    m.onset_where = where_of(t, "onset");
    {
      Section o = t.sub("onset");
      const bool rule = o.has("rule"), var = o.has("variable");
      if (rule == var) o.fail(rule ? "variable" : "rule", "give exactly one of `rule: threshold` or `variable` (a marker)");
      if (rule) {
        o.choice("rule", {"threshold"});
        m.onset_mode = Mapping::OnsetMode::kThreshold;
        m.threshold_n = o.positive("threshold_n");
        if (o.has("zero_n")) m.zero_n = o.nonneg("zero_n");
        if (!(m.zero_n < m.threshold_n)) o.fail("zero_n", "must be below threshold_n");
        o.finish();
      } else {
        m.onset_mode = Mapping::OnsetMode::kMarker;
        // Re-read as a marker (same keys: variable, as).
        m.onset = read_marker(t, "onset");
      }
    }
    if (t.has("angle")) {
      m.angle_where = where_of(t, "angle");
      Section a = t.sub("angle");
      const bool rule = a.has("rule"), var = a.has("variable");
      if (rule == var) a.fail(rule ? "variable" : "rule", "give exactly one of `rule: from_force` or `variable`");
      if (rule) {
        a.choice("rule", {"from_force"});
        m.angle_mode = Mapping::AngleMode::kFromForce;
        if (a.has("round_deg")) m.angle_round_deg = a.nonneg("round_deg");
      } else {
        m.angle_mode = Mapping::AngleMode::kVariable;
        m.angle_variable = variable_name(a, "variable");
        std::string u;
        m.angle_to_rad = unit_factor(a, "unit", kAngle, "an angle", u);
      }
      a.finish();
    }
    if (t.has("targets")) {
      Section g = t.sub("targets");
      m.start_shoulder_m = g.vec2("start_shoulder_m");
      m.goal_shoulder_m = g.vec2("goal_shoulder_m");
      g.finish();
    }
    t.finish();
  }
  {  // session constants: no defaults for what describes another rig or person
    Section s = top.sub("session");
    auto& d = m.session;
    d.source = s.has("source") ? s.string("source") : std::string("manip_import");
    d.participant_id = s.string("participant_id");
    d.session_id = s.string("session_id");
    if (s.has("utime_start_us")) d.utime_start_us = s.integer("utime_start_us", 0, 4102444800000000LL);
    if (s.has("drive_rate_hz")) {
      d.drive_rate_hz = s.positive("drive_rate_hz");
      m.drive_rate_given = true;
    }
    {
      Section a = s.sub("admittance");
      d.m_adm_kg = a.vec2_positive("m_adm_kg");
      d.d_adm_nspm = a.vec2_nonneg("d_adm_nspm");
      a.finish();
    }
    d.m_handle_kg = s.vec2_nonneg("m_handle_kg");
    {
      Section a = s.sub("anthropometrics");
      const Vec2 l = a.vec2_positive("segment_length_m"), ms = a.vec2_positive("segment_mass_kg"),
                 c = a.vec2_nonneg("segment_com_m"), in = a.vec2_positive("segment_inertia_kgm2");
      for (int i = 0; i < 2; ++i) {
        d.anthropometrics.length_m[i] = l[i];
        d.anthropometrics.mass_kg[i] = ms[i];
        d.anthropometrics.com_m[i] = c[i];
        d.anthropometrics.inertia_kgm2[i] = in[i];
      }
      if (a.has("body_mass_kg")) d.body_mass_kg = a.nonneg("body_mass_kg");
      if (a.has("body_height_m")) d.body_height_m = a.nonneg("body_height_m");
      if (const auto why = d.anthropometrics.invalid_reason()) a.fail("segment_length_m", *why);
      a.finish();
    }
    {
      Section p = s.sub("perturbation");
      d.perturbation.duration_s = p.positive("duration_s");
      d.perturbation.amplitude_n = p.positive("amplitude_n");
      d.perturbation.trigger_x2_shoulder_m = p.any_number("trigger_x2_shoulder_m");
      p.finish();
    }
    s.finish();
  }
  top.finish();
  m.session.frame = m.frame;
  m.session.config_yaml = text;
  return m;
}

Mapping load_mapping(const std::string& path) { return parse_mapping(yaml::read_text_file(path), path); }

}  // namespace manip::importer
