#include "manip/diagnosis/single_joint.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <charconv>
#include <cmath>
#include <fstream>
#include <memory>
#include <sstream>
#include <string_view>

#include "manip/common/errors.hpp"
#include "manip/diagnosis/engine.hpp"
#include "manip/diagnosis/report.hpp"
#include "manip/dsp/savgol.hpp"

namespace manip::diagnosis {
namespace {

std::string trim(std::string_view s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string_view::npos) return {};
  const auto e = s.find_last_not_of(" \t\r");
  return std::string(s.substr(b, e - b + 1));
}

std::vector<std::string> split_fields(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  std::istringstream is(line);
  while (std::getline(is, cur, ',')) out.push_back(trim(cur));
  if (!line.empty() && line.back() == ',') out.emplace_back();
  return out;
}

bool parse_double(const std::string& s, double& v) {
  if (s.empty()) return false;
  const char* b = s.data();
  const char* e = s.data() + s.size();
  if (*b == '+') ++b;
  auto [ptr, ec] = std::from_chars(b, e, v);
  return ec == std::errc() && ptr == e && std::isfinite(v);
}

// "['pos1', 'tq1']" (a MATLAB/Python export's channel list) -> {pos1, tq1}
std::vector<std::string> parse_channel_list(std::string_view s) {
  const auto close = s.find(']');
  if (close != std::string_view::npos) s = s.substr(0, close);
  std::vector<std::string> out;
  std::string cur;
  auto flush = [&] {
    const auto n = trim(cur);
    if (!n.empty()) out.push_back(n);
    cur.clear();
  };
  for (char ch : s) {
    if (ch == ',' || ch == ';') flush();
    else if (ch != '[' && ch != '\'' && ch != '"') cur += ch;
  }
  flush();
  return out;
}

struct ChannelMap {
  int time = -1, pos = -1, torque = -1;
  std::string error;
};

// Channel names carry no units in such exports (the ankle records' "pos1",
// "tq1"): the layout's units (rad, N m) are assumed, and a name that says
// degrees is refused rather than silently taken as radians. A role found
// twice is ambiguous and leaves the mapping to the positional layout or to
// a header line.
ChannelMap classify_channels(const std::vector<std::string>& names) {
  ChannelMap m;
  int n_pos = 0, n_torque = 0, n_time = 0;
  for (std::size_t i = 0; i < names.size(); ++i) {
    std::string l = names[i];
    for (auto& ch : l) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    const auto has = [&](const char* w) { return l.find(w) != std::string::npos; };
    const auto starts = [&](const char* w) { return l.rfind(w, 0) == 0; };
    const int idx = static_cast<int>(i);
    if (l == "t" || l == "t_s" || starts("time")) {
      m.time = idx;
      ++n_time;
    } else if (starts("pos") || has("angle") || has("theta")) {
      if (has("deg")) {
        m.error = "channel '" + names[i] + "' looks like degrees; the layout needs radians";
        return m;
      }
      m.pos = idx;
      ++n_pos;
    } else if (starts("tq") || starts("trq") || has("torque") || has("moment")) {
      m.torque = idx;
      ++n_torque;
    }
  }
  if (n_pos != 1 || n_torque != 1 || n_time > 1) return ChannelMap{};
  return m;
}

}  // namespace

SingleJointRecord read_single_joint_csv(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot open (" + std::string(std::strerror(errno)) + ")");
  SingleJointRecord rec;
  rec.source = path;
  double dt_header = 0.0;
  bool have_dt_header = false;
  std::vector<std::string> channels;  // from a "channels=[...]" comment
  int channels_line = 0;
  int col_t = -1, col_p = -1, col_q = -1, ncols = -1;
  std::vector<std::string> names;  // of the columns, when known
  std::vector<double> time;
  std::string line;
  int lineno = 0;
  auto fail = [&](const std::string& why) { throw InputError(path + ":" + std::to_string(lineno) + ": " + why); };
  auto name_list = [](const std::vector<std::string>& n) {
    std::string out;
    for (const auto& x : n) out += (out.empty() ? "" : ", ") + x;
    return out;
  };
  while (std::getline(in, line)) {
    ++lineno;
    const std::string t = trim(line);
    if (t.empty()) fail("empty line (remove it)");
    if (t[0] == '#') {
      const auto k = t.find("dt=");
      if (k != std::string::npos) {
        if (have_dt_header) fail("second \"dt=\"");
        std::size_t e = k + 3;
        while (e < t.size() && t[e] != ';' && t[e] != ' ' && t[e] != ',') ++e;
        if (!parse_double(t.substr(k + 3, e - k - 3), dt_header) || !(dt_header > 0.0))
          fail("\"dt=\" must be a positive number of seconds (got \"" + t.substr(k + 3, e - k - 3) + "\")");
        have_dt_header = true;
      }
      const auto c = t.find("channels=");
      if (c != std::string::npos) {
        if (channels_line) fail("second \"channels=\"");
        channels = parse_channel_list(t.substr(c + 9));
        if (channels.empty()) fail("\"channels=\" names no channel");
        channels_line = lineno;
      }
      continue;
    }
    const auto f = split_fields(t);
    if (ncols < 0) {
      ncols = static_cast<int>(f.size());
      double probe = 0.0;
      if (!parse_double(f[0], probe)) {  // column-header line: the unit-carrying names, other columns ignored
        names = f;
        for (int i = 0; i < ncols; ++i) {
          const auto& name = f[static_cast<std::size_t>(i)];
          int* slot = name == "time_s" ? &col_t : name == "pos_rad" ? &col_p : name == "torque_nm" ? &col_q : nullptr;
          if (!slot) continue;
          if (*slot >= 0) fail("column \"" + name + "\" given twice");
          *slot = i;
        }
        if (col_p < 0 || col_q < 0)
          fail("header must name pos_rad and torque_nm (columns: " + name_list(f) + ")");
        continue;
      }
      if (!channels.empty()) {
        if (static_cast<int>(channels.size()) != ncols)
          fail("\"channels=\" (line " + std::to_string(channels_line) + ") names " + std::to_string(channels.size()) +
               " channels, the data has " + std::to_string(ncols) + " fields");
        const auto m = classify_channels(channels);
        if (!m.error.empty()) fail("\"channels=\" (line " + std::to_string(channels_line) + "): " + m.error);
        if (m.pos >= 0 && m.torque >= 0) {
          col_t = m.time;
          col_p = m.pos;
          col_q = m.torque;
          names = channels;
        }
      }
      if (col_p < 0) {
        if (ncols == 2) {
          col_p = 0;
          col_q = 1;
        } else if (ncols == 3) {
          col_t = 0;
          col_p = 1;
          col_q = 2;
        } else {
          fail("expected 2 columns (pos_rad, torque_nm) or 3 (time_s, pos_rad, torque_nm), got " + std::to_string(ncols) +
               (channels.empty() ? "" : " and \"channels=\" names no single position and torque channel (" +
                                            name_list(channels) + ")") +
               "; a header line naming pos_rad and torque_nm selects columns (others are ignored)");
        }
      }
    }
    if (static_cast<int>(f.size()) != ncols)
      fail("expected " + std::to_string(ncols) + " fields, got " + std::to_string(f.size()));
    double v[3] = {0, 0, 0};
    const int used[3] = {col_t, col_p, col_q};
    for (int u = 0; u < 3; ++u) {
      const int i = used[u];
      if (i < 0) continue;
      if (!parse_double(f[static_cast<std::size_t>(i)], v[u]))
        fail("field " + std::to_string(i + 1) + " is not a finite number (\"" + f[static_cast<std::size_t>(i)] + "\")");
    }
    if (col_t >= 0) time.push_back(v[0]);
    rec.pos_rad.push_back(v[1]);
    rec.torque_nm.push_back(v[2]);
  }
  if (!names.empty() && !(ncols == 2 && col_p == 0 && col_q == 1) && !(ncols == 3 && col_t == 0 && col_p == 1 && col_q == 2)) {
    auto col = [&](int i) { return "'" + names[static_cast<std::size_t>(i)] + "' (" + std::to_string(i + 1) + ")"; };
    rec.columns_note = "columns by name: position " + col(col_p) + ", torque " + col(col_q);
    if (col_t >= 0) rec.columns_note += ", time " + col(col_t);
    std::vector<std::string> ignored;
    for (int i = 0; i < ncols; ++i)
      if (i != col_t && i != col_p && i != col_q) ignored.push_back(col(i));
    if (!ignored.empty()) rec.columns_note += "; ignored " + name_list(ignored);
  }
  if (rec.pos_rad.size() < 2) throw InputError(path + ": no data rows (need position and torque samples)");
  if (col_t >= 0) {
    const double dt = (time.back() - time.front()) / static_cast<double>(time.size() - 1);
    if (!(dt > 0.0)) throw InputError(path + ": time_s does not increase");
    for (std::size_t i = 1; i < time.size(); ++i)
      if (std::fabs(time[i] - time[i - 1] - dt) > 1e-3 * dt) {
        lineno = 0;
        throw InputError(path + ": time_s not uniformly sampled near sample " + std::to_string(i) +
                         " (step " + std::to_string(time[i] - time[i - 1]) + " s, mean " + std::to_string(dt) + " s)");
      }
    if (have_dt_header && std::fabs(dt - dt_header) > 1e-3 * dt_header)
      throw InputError(path + ": time_s spacing " + std::to_string(dt) + " s disagrees with dt=" +
                       std::to_string(dt_header));
    rec.dt_s = dt;
  } else {
    if (!have_dt_header) throw InputError(path + ": no time_s column and no \"# dt=<seconds>\" line: sample period unknown");
    rec.dt_s = dt_header;
  }
  return rec;
}

SingleJointPrepared prepare_single_joint(const SingleJointRecord& rec, const SingleJointOptions& opt) {
  SingleJointPrepared out;
  const double fs = 1.0 / rec.dt_s;
  const double fc = std::min(opt.cutoff_hz, fs / 8.0);
  out.window = dsp::savgol_window_for_cutoff(fs, fc, opt.polyorder);
  out.cutoff_hz = dsp::savgol_cutoff_hz(out.window, opt.polyorder, fs);
  const std::size_t n = rec.pos_rad.size();
  if (n < static_cast<std::size_t>(4 * out.window))
    throw InputError(rec.source + ": " + std::to_string(n) + " samples are too few (need several Savitzky-Golay windows of " +
                     std::to_string(out.window) + ")");
  auto smooth = std::make_shared<dsp::SavgolFilter>(out.window, opt.polyorder, 0, rec.dt_s);
  dsp::SavgolFilter d1(out.window, opt.polyorder, 1, rec.dt_s);
  dsp::SavgolFilter d2(out.window, opt.polyorder, 2, rec.dt_s);
  Segment s;
  s.pos.resize(n);
  s.vel.resize(n);
  s.acc.resize(n);
  s.y.resize(n);
  s.pos_raw = rec.pos_rad;
  smooth->apply(rec.pos_rad, s.pos);
  d1.apply(rec.pos_rad, s.vel);
  d2.apply(rec.pos_rad, s.acc);
  smooth->apply(rec.torque_nm, s.y);
  // Edges: mode='interp' fits one polynomial to the first/last window; keep
  // only samples whose window lies inside the record.
  s.first = static_cast<std::size_t>(out.window / 2);
  s.last = n - static_cast<std::size_t>(out.window / 2);
  s.t0_s = 0.0;
  Dataset& d = out.data;
  d.source = rec.source;
  d.dt_s = rec.dt_s;
  d.smoother = smooth;
  d.smoothing_cutoff_hz = out.cutoff_hz;
  d.target_name = "torque";
  d.target_unit = "N m";
  d.kin_unit = "rad";
  d.inertia_fixed = opt.inertia_fixed;
  d.fixed_inertia = opt.fixed_inertia_kgm2;
  const double pos_mean = [&] {
    double m = 0.0;
    for (std::size_t i = s.first; i < s.last; ++i) m += s.pos[i];
    return m / static_cast<double>(s.last - s.first);
  }();
  d.pos_ref = pos_mean;
  std::vector<double> pc(n);
  for (std::size_t i = 0; i < n; ++i) pc[i] = s.pos[i] - pos_mean;
  // Torque sign (see SingleJointOptions::torque_sign): decided on the free
  // four-term fit so that it does not depend on a fixed inertia.
  out.torque_sign = opt.torque_sign == 0 ? 1 : opt.torque_sign;
  if (opt.torque_sign == 0) {
    Eigen::Matrix4d G = Eigen::Matrix4d::Zero();
    Eigen::Vector4d h = Eigen::Vector4d::Zero();
    for (std::size_t i = s.first; i < s.last; ++i) {
      const Eigen::Vector4d x(s.acc[i], s.vel[i], pc[i], 1.0);
      G += x * x.transpose();
      h += x * s.y[i];
    }
    const Eigen::Vector4d th = G.completeOrthogonalDecomposition().solve(h);
    if (th(2) < 0.0) {
      out.torque_sign = -1;
      out.sign_flipped_automatically = true;
    }
  }
  for (auto& v : s.y) v *= out.torque_sign;
  if (opt.inertia_fixed) {
    for (std::size_t i = 0; i < n; ++i) s.y[i] -= opt.fixed_inertia_kgm2 * s.acc[i];
  } else {
    d.base_names.push_back("I");
    d.base_units.push_back("kg m^2");
    s.base.push_back(s.acc);
  }
  d.base_names.insert(d.base_names.end(), {"B", "K", "c"});
  d.base_units.insert(d.base_units.end(), {"N m s/rad", "N m/rad", "N m"});
  s.base.push_back(s.vel);
  s.base.push_back(pc);
  s.base.emplace_back(n, 1.0);
  d.segments.push_back(std::move(s));
  return out;
}

std::vector<PhysicalCheck> single_joint_physical_checks(const Diagnosis& d) {
  std::vector<PhysicalCheck> out;
  const auto* b = d.find_baseline("B");
  const auto* k = d.find_baseline("K");
  const auto* i = d.find_baseline("I");
  // Only when the whole interval is below zero: a B near 0 is within its noise.
  if (b && k && b->est.hi < 0.0 && k->est.value > 0.0) {
    PhysicalCheck c;
    c.what = "B < 0";
    c.least_lag_s = -b->est.value / k->est.value;
    c.text = "baseline B " + g4(b->est.value) + " N m s/rad < 0, which a passive joint cannot have: a lag T of the torque channel "
             "behind the position channel reads as B - T K (and I - T B + T^2 K), here T >= -B/K = " + g4(c.least_lag_s * 1e3) +
             " ms (the torque-channel lag fit above separates it from B and I when the response carries enough of it; a rigid "
             "load times the channels for certain), or the channels' sign conventions differ";
    out.push_back(c);
  }
  if (i && i->est.hi < 0.0) {
    PhysicalCheck c;
    c.what = "I < 0";
    c.text = "baseline I " + g4(i->est.value) + " kg m^2 < 0, which a foot and pedal cannot have: the acceleration carries a lag "
             "between the channels or a filter on one of them (I - T B + T^2 K for a torque lag T)";
    out.push_back(c);
  }
  return out;
}

}  // namespace manip::diagnosis
