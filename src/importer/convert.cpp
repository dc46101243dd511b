#include "manip/importer/convert.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <sstream>

#include "manip/common/errors.hpp"
#include "manip/common/output_file.hpp"
#include "manip/schema/codes.hpp"
#include "manip/version.hpp"

namespace manip::importer {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kDeg = std::numbers::pi / 180.0;  // the same constant the simulator uses

std::string num(double v) {
  std::ostringstream o;
  o.precision(10);
  o << v;
  return o.str();
}

// Resolves names against the dataset with messages that name both files.
class Resolver {
 public:
  Resolver(const Mapping& m, const Dataset& ds) : m_(m), ds_(ds) {}

  const Variable& variable(const std::string& name, const Where& w) const {
    if (const Variable* v = ds_.find(name)) return *v;
    const auto u = ds_.unusable.find(name);
    if (u != ds_.unusable.end())
      throw ConfigError(w.str() + ": variable '" + name + "' in " + ds_.path + " is " + u->second +
                        "; expected a numeric matrix");
    throw ConfigError(w.str() + ": variable '" + name + "' not found in " + ds_.path + " (" + ds_.format +
                      "; it holds: " + ds_.names() + ")");
  }

  // A vector of n values (N x 1 or 1 x N); n = 0: any length.
  std::vector<double> vector(const std::string& name, const Where& w, std::size_t n, const std::string& n_why) const {
    const Variable& v = variable(name, w);
    if (v.rows != 1 && v.cols != 1)
      throw ConfigError(w.str() + ": variable '" + name + "' in " + ds_.path + " is " + v.dims() +
                        "; expected a vector (N x 1 or 1 x N)");
    if (n != 0 && v.numel() != n)
      throw ConfigError(w.str() + ": variable '" + name + "' in " + ds_.path + " has " + std::to_string(v.numel()) +
                        " values; expected " + std::to_string(n) + " (" + n_why + ")");
    return v.data;
  }

  // Number of samples implied by a signal (used when only a sample rate is given).
  std::size_t samples_of(const SignalSpec& s) const {
    const Variable& v = variable(s.variables[0], s.where);
    if (s.variables.size() == 2 || v.rows == 1 || v.cols == 1) return v.numel();
    return v.rows >= v.cols ? v.rows : v.cols;
  }

  // The two components in SI, as recorded (before the axis map).
  std::vector<Vec2> signal(const SignalSpec& s, std::size_t n, const std::string& n_why) const {
    std::vector<Vec2> out(n);
    if (s.variables.size() == 2) {
      for (int c = 0; c < 2; ++c) {
        const auto v = vector(s.variables[static_cast<std::size_t>(c)], s.where, n, n_why);
        for (std::size_t i = 0; i < n; ++i) out[i](c) = v[i] * s.to_si;
      }
      return out;
    }
    const Variable& v = variable(s.variables[0], s.where);
    const auto need = static_cast<std::size_t>(std::max(s.columns[0], s.columns[1]));
    const std::string expect = "expected " + std::to_string(n) + " x k with k >= " + std::to_string(need) + " (" +
                               n_why + ")";
    bool transposed = false;
    if (v.rows == n && v.cols >= need) {
      transposed = false;
    } else if (v.cols == n && v.rows >= need && v.rows != n) {
      transposed = true;  // k x N, as some scripts store channels in rows
    } else {
      throw ConfigError(s.where.str() + ": variable '" + s.variables[0] + "' in " + ds_.path + " is " + v.dims() +
                        "; " + expect);
    }
    for (int c = 0; c < 2; ++c) {
      const auto col = static_cast<std::size_t>(s.columns[static_cast<std::size_t>(c)] - 1);
      for (std::size_t i = 0; i < n; ++i) out[i](c) = (transposed ? v.at(col, i) : v.at(i, col)) * s.to_si;
    }
    return out;
  }

  [[nodiscard]] const Dataset& ds() const { return ds_; }
  [[nodiscard]] const Mapping& m() const { return m_; }

 private:
  const Mapping& m_;
  const Dataset& ds_;
};

struct Span {
  int number{-1};
  std::size_t start{0}, end{0};  // inclusive sample indices
  std::optional<std::size_t> onset;
  double angle_rad{0.0};
};

// Sample indices of a marker (see MarkerSpec).
std::vector<std::size_t> marker_samples(const Resolver& r, const MarkerSpec& mk, const std::vector<double>& t_s,
                                        const std::string& n_why) {
  const std::size_t n = t_s.size();
  const std::string in = " in " + r.ds().path + " (variable '" + mk.variable + "', " + mk.where.str() + ")";
  std::vector<std::size_t> out;
  if (mk.as == MarkerSpec::As::kFlag) {
    const auto v = r.vector(mk.variable, mk.where, n, n_why);
    bool prev = false;
    for (std::size_t i = 0; i < n; ++i) {
      const bool on = std::isfinite(v[i]) && v[i] != 0.0;
      if (on && !prev) out.push_back(i);
      prev = on;
    }
    return out;
  }
  const auto v = r.vector(mk.variable, mk.where, 0, "");
  const double dt = n > 1 ? (t_s.back() - t_s.front()) / static_cast<double>(n - 1) : 0.0;
  for (std::size_t k = 0; k < v.size(); ++k) {
    const double x = v[k];
    if (!std::isfinite(x)) continue;  // NaN padding of a per-trial list
    if (mk.as == MarkerSpec::As::kIndex) {
      if (std::abs(x - std::round(x)) > 1e-9 || x < 1 || x > static_cast<double>(n))
        throw InputError("marker " + std::to_string(k + 1) + in + ": " + num(x) +
                         " is not a 1-based sample index in [1, " + std::to_string(n) + "]");
      out.push_back(static_cast<std::size_t>(std::llround(x)) - 1);
    } else {
      const double ts = x * r.m().time_to_s;
      const auto it = std::lower_bound(t_s.begin(), t_s.end(), ts);
      std::size_t i = static_cast<std::size_t>(it - t_s.begin());
      if (i == n || (i > 0 && ts - t_s[i - 1] < t_s[i] - ts)) i = i == 0 ? 0 : i - 1;
      if (std::abs(t_s[i] - ts) > 0.5 * dt + 1e-12)
        throw InputError("marker " + std::to_string(k + 1) + in + ": time " + num(x) +
                         " is not within half a sample of any sample time (recording spans " + num(t_s.front()) +
                         " to " + num(t_s.back()) + " s)");
      out.push_back(i);
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

ImportSummary convert(const Mapping& m, const Dataset& ds, logging::SessionHandler& out) {
  const Resolver r(m, ds);
  ImportSummary sum;
  sum.input_format = ds.format;

  // ---- time base
  std::vector<double> t_s;
  std::string n_why;
  double fs = m.sample_rate_hz;
  if (!m.time_variable.empty()) {
    Where tw = m.time_where;
    tw.key += ".variable";
    t_s = r.vector(m.time_variable, tw, 0, "");
    for (auto& x : t_s) x *= m.time_to_s;
    const std::string in = ds.path + ": variable '" + m.time_variable + "' (" + tw.str() + ")";
    if (t_s.size() < 2) throw InputError(in + ": fewer than two samples");
    for (std::size_t i = 0; i < t_s.size(); ++i) {
      if (!std::isfinite(t_s[i])) throw InputError(in + ": time is not finite at sample " + std::to_string(i + 1));
      if (i > 0 && !(t_s[i] > t_s[i - 1]))
        throw InputError(in + ": time does not increase at sample " + std::to_string(i + 1) + " (" + num(t_s[i]) +
                         " s after " + num(t_s[i - 1]) + " s); the time base must be strictly increasing");
    }
    const double dt = (t_s.back() - t_s.front()) / static_cast<double>(t_s.size() - 1);
    for (std::size_t i = 1; i < t_s.size(); ++i) {
      const double d = t_s[i] - t_s[i - 1];
      if (std::abs(d - dt) > m.max_jitter * dt)
        throw InputError(in + ": sample interval " + num(d) + " s at sample " + std::to_string(i + 1) +
                         " differs from the mean " + num(dt) + " s by more than time.max_jitter (" +
                         num(m.max_jitter * 100) + " %); a gap or a changed rate cannot be imported (the estimator " +
                         "needs equally spaced samples)");
    }
    fs = 1.0 / dt;
    // Rigs run at a whole number of hertz; the rate estimated from stored
    // times differs from it only by rounding, which should not leak into the
    // filters the estimator designs from session_t.sample_rate_hz.
    if (const double rounded = std::round(fs); std::abs(fs - rounded) <= 1e-6 * fs) fs = rounded;
    n_why = "N = " + std::to_string(t_s.size()) + " samples, as the time variable '" + m.time_variable + "'";
  } else {
    const std::size_t n = r.samples_of(m.position);
    if (n < 2) throw ConfigError(m.position.where.str() + ": fewer than two samples");
    t_s.resize(n);
    for (std::size_t i = 0; i < n; ++i) t_s[i] = static_cast<double>(i) / fs;
    n_why = "N = " + std::to_string(n) + " samples, as signals.position";
  }
  const std::size_t n = t_s.size();
  sum.samples = static_cast<std::int64_t>(n);
  sum.sample_rate_hz = fs;
  sum.duration_s = static_cast<double>(n - 1) / fs;

  // ---- signals: recorded components -> workspace axes (axis map, signs)
  auto to_workspace = [&](std::vector<Vec2> rec) {
    for (auto& v : rec) {
      const Vec2 c = v;
      for (int i = 0; i < 2; ++i) {
        const int a = m.axes[static_cast<std::size_t>(i)];
        v(i) = (a < 0 ? -1.0 : 1.0) * c(std::abs(a) - 1);
      }
    }
    return rec;
  };
  const auto x_ws = to_workspace(r.signal(m.position, n, n_why));
  const auto f_ws = to_workspace(r.signal(m.handle_force, n, n_why));
  const auto u_ws = to_workspace(r.signal(m.perturbation_force, n, n_why));

  // ---- trials
  std::vector<Span> spans;
  if (m.trial_mode == Mapping::TrialMode::kIndex) {
    Where w = m.index_where;
    w.key += ".variable";
    const auto idx = r.vector(m.index_variable, w, n, n_why);
    const std::string in = ds.path + ": variable '" + m.index_variable + "' (" + w.str() + ")";
    std::vector<int> seen;
    for (std::size_t i = 0; i < n; ++i) {
      const double v = idx[i];
      const bool outside = !std::isfinite(v) || v == m.index_outside || v < static_cast<double>(m.index_first);
      if (outside) continue;
      if (std::abs(v - std::round(v)) > 1e-9)
        throw InputError(in + ": trial index " + num(v) + " at sample " + std::to_string(i + 1) + " is not a whole number");
      const int number = static_cast<int>(std::llround(v) - m.index_first);
      if (!spans.empty() && spans.back().number == number && spans.back().end + 1 == i) {
        spans.back().end = i;
        continue;
      }
      if (std::find(seen.begin(), seen.end(), number) != seen.end())
        throw InputError(in + ": trial " + num(v) + " appears again at sample " + std::to_string(i + 1) +
                         " after other samples (a trial must be one contiguous run of samples)");
      seen.push_back(number);
      spans.push_back(Span{number, i, i, std::nullopt, 0.0});
    }
  } else {
    const auto st = marker_samples(r, m.start, t_s, n_why);
    const auto en = marker_samples(r, m.end, t_s, n_why);
    if (st.size() != en.size())
      throw InputError(ds.path + ": " + std::to_string(st.size()) + " trial starts (variable '" + m.start.variable +
                       "', " + m.start.where.str() + ") but " + std::to_string(en.size()) + " trial ends (variable '" +
                       m.end.variable + "', " + m.end.where.str() + ")");
    for (std::size_t k = 0; k < st.size(); ++k) {
      if (en[k] < st[k] || (k + 1 < st.size() && st[k + 1] <= en[k]))
        throw InputError(ds.path + ": trial " + std::to_string(k + 1) + " (" + m.start.where.str() + ", " +
                         m.end.where.str() + "): starts at sample " + std::to_string(st[k] + 1) + " and ends at " +
                         std::to_string(en[k] + 1) +
                         (k + 1 < st.size() ? ", next start at " + std::to_string(st[k + 1] + 1) : std::string()) +
                         "; trials must not overlap and must end after they start");
      spans.push_back(Span{static_cast<int>(k), st[k], en[k], std::nullopt, 0.0});
    }
  }
  if (spans.empty())
    throw InputError(ds.path + ": no trial found (" +
                     (m.trial_mode == Mapping::TrialMode::kIndex ? m.index_where.str() : m.start.where.str()) + ")");

  // ---- onsets
  if (m.onset_mode == Mapping::OnsetMode::kThreshold) {
    for (auto& s : spans) {
      std::size_t i = s.start;
      while (i <= s.end && !(u_ws[i].norm() > m.threshold_n)) ++i;
      if (i > s.end) continue;  // never above threshold: unperturbed
      // manip's ONSET is the cycle whose force is still zero and rises from
      // the next (docs/conventions.md): walk back to the last sample at or
      // below zero_n; a smooth profile crosses the threshold several samples
      // after it has started.
      std::size_t j = i;
      while (j > s.start && u_ws[j].norm() > m.zero_n) --j;
      if (u_ws[j].norm() > m.zero_n)
        sum.notes.push_back("trial " + std::to_string(s.number) +
                            ": perturbation force already above onset.zero_n at the trial's first sample; onset set there");
      s.onset = j;
    }
  } else {
    const auto on = marker_samples(r, m.onset, t_s, n_why);
    for (const std::size_t i : on) {
      auto it = std::find_if(spans.begin(), spans.end(), [&](const Span& s) { return i >= s.start && i <= s.end; });
      if (it == spans.end())
        throw InputError(ds.path + ": onset marker at sample " + std::to_string(i + 1) + " (variable '" +
                         m.onset.variable + "', " + m.onset.where.str() + ") lies outside every trial");
      if (it->onset)
        throw InputError(ds.path + ": two onset markers in trial " + std::to_string(it->number) + " (samples " +
                         std::to_string(*it->onset + 1) + " and " + std::to_string(i + 1) + "; variable '" +
                         m.onset.variable + "', " + m.onset.where.str() + ")");
      it->onset = i;
    }
  }

  // Non-finite samples inside a trial make the estimator exclude it; say so
  // here, where the recording can still be fixed.
  for (const auto& s : spans) {
    std::size_t bad = 0, first_bad = 0;
    for (std::size_t i = s.start; i <= s.end; ++i)
      if (!x_ws[i].allFinite() || !f_ws[i].allFinite() || !u_ws[i].allFinite()) {
        if (bad++ == 0) first_bad = i;
      }
    if (bad > 0)
      sum.notes.push_back("trial " + std::to_string(s.number) + ": " + std::to_string(bad) +
                          " samples with a non-finite position or force (first at sample " +
                          std::to_string(first_bad + 1) + "); estimate_impedance will exclude this trial");
  }

  // ---- angles (shoulder frame)
  const Mat2 rot = m.frame.rotation();
  const auto pert_samples = static_cast<std::size_t>(std::ceil(m.session.perturbation.duration_s * fs));
  if (m.angle_mode == Mapping::AngleMode::kFromForce) {
    for (auto& s : spans) {
      if (!s.onset) continue;
      std::size_t peak = *s.onset;
      for (std::size_t i = *s.onset; i <= std::min(s.end, *s.onset + pert_samples); ++i)
        if (u_ws[i].norm() > u_ws[peak].norm()) peak = i;
      const Vec2 u = rot * u_ws[peak];
      double deg = std::atan2(u(1), u(0)) / kDeg;
      if (m.angle_round_deg > 0) deg = std::round(deg / m.angle_round_deg) * m.angle_round_deg;
      deg = std::fmod(deg + 360.0, 360.0);
      s.angle_rad = deg * kDeg;
    }
  } else {
    Where w = m.angle_where;
    w.key += ".variable";
    const auto v = r.vector(m.angle_variable, w, 0, "");
    if (v.size() != n && v.size() != spans.size())
      throw ConfigError(w.str() + ": variable '" + m.angle_variable + "' in " + ds.path + " has " +
                        std::to_string(v.size()) + " values; expected one per sample (" + std::to_string(n) +
                        ") or one per trial (" + std::to_string(spans.size()) + ")");
    for (std::size_t k = 0; k < spans.size(); ++k) {
      auto& s = spans[k];
      if (!s.onset) continue;
      const double a = v.size() == n ? v[*s.onset] : v[k];
      if (!std::isfinite(a))
        throw InputError(ds.path + ": variable '" + m.angle_variable + "' (" + w.str() + "): angle of trial " +
                         std::to_string(s.number) + " is not finite");
      s.angle_rad = a * m.angle_to_rad;
    }
  }

  // ---- session message
  schema::SessionDescription d = m.session;
  d.software_version = kVersion;
  d.sample_rate_hz = fs;
  if (!m.drive_rate_given) d.drive_rate_hz = fs;  // unknown: the drives are taken to run at the sample rate
  if (const auto why = d.invalid_reason())
    throw ConfigError(m.file + ": session: " + *why + " (sample rate from the " +
                      (m.time_variable.empty() ? std::string("mapping") : "time variable '" + m.time_variable + "'") +
                      ")");
  out.on_session(schema::to_message(d));

  // ---- stream
  auto utime_of = [&](std::size_t i) { return d.utime_start_us + std::llround((t_s[i] - t_s[0]) * 1e6); };
  auto event = [&](const Span& s, std::int8_t kind, std::size_t i) {
    manip::trial_event_t e{};
    e.utime = utime_of(i);
    e.cycle = static_cast<std::int64_t>(i);
    e.trial = s.number;
    e.kind = kind;
    e.perturbed = s.onset.has_value();
    for (int k = 0; k < 2; ++k) {
      e.start_shoulder_m[k] = m.start_shoulder_m[k];
      e.goal_shoulder_m[k] = m.goal_shoulder_m[k];
    }
    e.pert_angle_rad = s.onset ? s.angle_rad : 0.0;
    e.pert_amplitude_n = s.onset ? d.perturbation.amplitude_n : 0.0;
    e.pert_duration_s = s.onset ? d.perturbation.duration_s : 0.0;
    out.on_trial_event(e);
  };
  std::size_t k = 0;  // current or next span
  for (std::size_t i = 0; i < n; ++i) {
    while (k < spans.size() && spans[k].end < i) ++k;
    const bool inside = k < spans.size() && i >= spans[k].start;
    if (inside && i == spans[k].start) event(spans[k], manip::trial_event_t::START, i);
    manip::state_t st{};
    st.cycle = static_cast<std::int64_t>(i);
    st.utime = utime_of(i);
    st.trial = inside ? spans[k].number : -1;
    auto phase = schema::Phase::kReturn;
    if (inside) {
      phase = schema::Phase::kReach;
      if (spans[k].onset && i >= *spans[k].onset && i < *spans[k].onset + pert_samples)
        phase = schema::Phase::kPerturbation;
    }
    st.phase = static_cast<std::int8_t>(phase);
    for (int a = 0; a < 2; ++a) {
      st.x_workspace_m[a] = x_ws[i](a);
      st.f_sensor_workspace_n[a] = f_ws[i](a);
      st.u_pert_workspace_n[a] = u_ws[i](a);
      // Not in a foreign recording (docs/import.md): NaN, never a made-up value.
      st.xd_workspace_mps[a] = kNaN;
      st.x_ref_workspace_m[a] = kNaN;
      st.xd_ref_workspace_mps[a] = kNaN;
      st.xdd_ref_workspace_mps2[a] = kNaN;
      st.f_motor_n[a] = kNaN;
    }
    st.mode = static_cast<std::int8_t>(schema::Mode::kRunning);
    st.fault_flags = 0;
    out.on_state(st);
    if (inside && spans[k].onset && i == *spans[k].onset) event(spans[k], manip::trial_event_t::ONSET, i);
    if (inside && i == spans[k].end) event(spans[k], manip::trial_event_t::END, i);
  }
  sum.trials = static_cast<int>(spans.size());
  for (const auto& s : spans) {
    sum.perturbed += s.onset ? 1 : 0;
    sum.mean_start_shoulder_m += m.frame.point_to_shoulder(x_ws[s.start]) / static_cast<double>(spans.size());
    sum.mean_end_shoulder_m += m.frame.point_to_shoulder(x_ws[s.end]) / static_cast<double>(spans.size());
  }
  return sum;
}

ImportSummary import_session(const std::string& mapping_path, const std::string& input_path,
                             const std::string& out_path, bool force) {
  const Mapping m = load_mapping(mapping_path);
  const Dataset ds = read_dataset(input_path);
  AtomicOutput target(out_path, force);
  ImportSummary sum;
  try {
    logging::LogWritingHandler w(target.temp_path());
    sum = convert(m, ds, w);
    w.close();
  } catch (const manip::Error&) {
    throw;
  } catch (const std::runtime_error& e) {  // the log writer's errors (disk full, ...)
    throw OutputError(out_path + ": " + e.what());
  }
  target.commit();
  return sum;
}

}  // namespace manip::importer
