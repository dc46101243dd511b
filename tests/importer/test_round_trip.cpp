// Round trip: a simulated session (the simulator's public API, written as a
// manip log) is exported the way other labs store sessions -- a CSV in mm with
// a 1-based trial-index column in a rotated, mirrored lab frame; a MAT v5 file
// with a struct of SI signals and 1-based marker indices; a MAT v7.3 file with
// channels in rows and a 0-based trial index -- imported through a mapping,
// and estimated. D and K must equal those of the original log.
//
// Tolerance. The imported signals differ from the original only by the
// rounding of the unit and frame conversions (an ulp or two per sample; the
// CSV is written with 17 significant digits, so the text is exact). What
// such a perturbation does to D and K is measured here, not guessed: the last
// test case multiplies the original's samples by 1 +- 4 ulp and re-estimates.
// The linear least-squares fits (paper, paper-pooled) move by ~1e-10
// relative; the default pem moves by ~2e-6 relative, because its iterative
// optimiser stops on a relative cost change of 1e-12, which leaves the
// parameters free to ~sqrt(1e-12) = 1e-6 along well-determined directions.
// Each element must therefore agree to within
//   max(3e-5 x the largest element of its matrix, 1e-3 x its own SE):
// ~10x the measured floor, and a thousandth of the statistical uncertainty
// (the per-trial fits of one push direction are poorly conditioned, and
// their SEs say so). A one-sample error in one trial's onset exceeds it by
// two orders of magnitude (the sensitivity test below), so the comparison
// catches real mapping errors.
#include <catch2/catch.hpp>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <numbers>
#include <sstream>

#include "fixtures.hpp"
#include "import_test_util.hpp"
#include "manip/estimation/session_estimator.hpp"
#include "manip/importer/convert.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"

using namespace manip;
namespace est = manip::estimation;
namespace ti = manip::test_import;

namespace {

constexpr double kRel = 3e-5;  // of the matrix's largest element
constexpr double kSe = 1e-3;   // of the element's own standard error

struct Original {
  std::string dir, log;
  testutil::Recorded rec;
  std::vector<manip::state_t> states;
  std::vector<manip::trial_event_t> events;
};

const Original& original() {
  static const Original o = [] {
    Original r;
    r.dir = testutil::temp_dir("importer_round_trip");
    auto d = testutil::small_design(12, 7);
    d.force_noise_n = 0.05;  // a sensor that is not perfect
    r.rec = testutil::record(d, sim::table1_person());
    r.log = r.dir + "/original.lcm";
    testutil::write_recorded(r.rec, r.log);
    for (const auto& it : r.rec.items) {
      if (it.kind == 0) r.states.push_back(it.state);
      if (it.kind == 1) r.events.push_back(it.event);
    }
    return r;
  }();
  return o;
}

std::string fmt(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

std::string vec(const double a[2]) { return "[" + fmt(a[0]) + ", " + fmt(a[1]) + "]"; }

// The session constants of the original, as a lab would type them.
std::string session_yaml(const manip::session_t& s) {
  std::ostringstream o;
  o << "session:\n"
    << "  participant_id: P07\n  session_id: rt-test\n"
    << "  admittance: {m_adm_kg: " << vec(s.m_adm_kg) << ", d_adm_nspm: " << vec(s.d_adm_nspm) << "}\n"
    << "  m_handle_kg: " << vec(s.m_handle_kg) << "\n"
    << "  anthropometrics:\n"
    << "    segment_length_m: " << vec(s.segment_length_m) << "\n"
    << "    segment_mass_kg: " << vec(s.segment_mass_kg) << "\n"
    << "    segment_com_m: " << vec(s.segment_com_m) << "\n"
    << "    segment_inertia_kgm2: " << vec(s.segment_inertia_kgm2) << "\n"
    << "  perturbation: {duration_s: " << fmt(s.pert_duration_s) << ", amplitude_n: " << fmt(s.pert_amplitude_n)
    << ", trigger_x2_shoulder_m: " << fmt(s.trigger_x2_shoulder_m) << "}\n";
  return o.str();
}

Vec2 v2(const double a[2]) { return Vec2(a[0], a[1]); }

// Shoulder-frame quantities of a state of the original log.
struct ShoulderSample {
  Vec2 x, f, u;
};
ShoulderSample to_shoulder(const manip::session_t& s, const manip::state_t& st) {
  WorkspaceToShoulder fr;
  fr.origin_in_shoulder_m = v2(s.workspace_origin_in_shoulder_m);
  fr.rot_rad = s.workspace_to_shoulder_rot_rad;
  return {fr.point_to_shoulder(v2(st.x_workspace_m)), fr.vector_to_shoulder(v2(st.f_sensor_workspace_n)),
          fr.vector_to_shoulder(v2(st.u_pert_workspace_n))};
}

// ---- the three lab layouts

// CSV: a lab frame rotated by 90 degrees with its first axis mirrored and its
// zero at (0.05, 0.40) m in the shoulder frame; mm; 1-based trial column
// (0 between trials); time in ms.
std::pair<std::string, std::string> export_csv(const Original& o) {
  WorkspaceToShoulder lab;
  lab.origin_in_shoulder_m = Vec2(0.05, 0.40);
  lab.rot_rad = std::numbers::pi / 2;
  auto rec_of = [](const Vec2& ws) { return Vec2(-ws(0), ws(1)); };  // mapping axes: [-1, 2]
  std::ostringstream c;
  c << "time_ms,trial,x_mm,y_mm,fx_N,fy_N,px_N,py_N\n";
  const auto c0 = o.states.front().cycle;
  for (const auto& st : o.states) {
    const auto sh = to_shoulder(o.rec.session, st);
    const Vec2 x = rec_of(lab.point_to_workspace(sh.x)) * 1000.0;
    const Vec2 f = rec_of(lab.vector_to_workspace(sh.f));
    const Vec2 u = rec_of(lab.vector_to_workspace(sh.u));
    c << fmt(static_cast<double>(st.cycle - c0) * 0.25) << "," << (st.trial < 0 ? 0 : st.trial + 1) << "," << fmt(x(0))
      << "," << fmt(x(1)) << "," << fmt(f(0)) << "," << fmt(f(1)) << "," << fmt(u(0)) << "," << fmt(u(1)) << "\n";
  }
  const std::string data = o.dir + "/lab.csv";
  ti::write_text(data, c.str());
  const std::string map = o.dir + "/lab-csv.yaml";
  ti::write_text(map, "time: {variable: time_ms, unit: ms}\n"
                      "signals:\n"
                      "  position: {variables: [x_mm, y_mm], unit: mm}\n"
                      "  handle_force: {variables: [fx_N, fy_N], unit: N}\n"
                      "  perturbation_force: {variables: [px_N, py_N], unit: N}\n"
                      "frame:\n"
                      "  axes: [-1, 2]\n"
                      "  origin_in_shoulder_m: [0.05, 0.40]\n"
                      "  rotation_deg: 90\n"
                      "trials:\n"
                      "  index: {variable: trial, outside: 0, first: 1}\n"
                      "  onset: {rule: threshold, threshold_n: 0.5}\n"
                      "  angle: {rule: from_force, round_deg: 1}\n" +
                          session_yaml(o.rec.session));
  return {map, data};
}

// MAT v5: struct `rec` in the original workspace frame, SI, trial and onset
// markers as 1-based sample indices, the angle per trial in degrees.
std::pair<std::string, std::string> export_mat5(const Original& o) {
  const std::size_t n = o.states.size();
  const auto c0 = o.states.front().cycle;
  ti::MatVar t{"t", n, 1, {}}, pos{"pos", n, 2, std::vector<double>(2 * n)}, frc{"force", n, 3, std::vector<double>(3 * n)},
      u{"u", n, 2, std::vector<double>(2 * n)};
  for (std::size_t i = 0; i < n; ++i) {
    const auto& st = o.states[i];
    t.data.push_back(static_cast<double>(st.cycle - c0) / 4000.0);
    for (std::size_t a = 0; a < 2; ++a) {
      pos.data[a * n + i] = st.x_workspace_m[a];
      frc.data[(a + 1) * n + i] = st.f_sensor_workspace_n[a];  // column 1 is another channel
      u.data[a * n + i] = st.u_pert_workspace_n[a];
    }
    frc.data[i] = 99.0;
  }
  ti::MatVar st_idx{"start_idx", 1, 0, {}}, en_idx{"end_idx", 1, 0, {}}, on_idx{"onset_idx", 1, 0, {}},
      phi{"phi_deg", 0, 1, {}};
  for (const auto& e : o.events) {
    const double idx1 = static_cast<double>(e.cycle - c0) + 1.0;
    if (e.kind == manip::trial_event_t::START) {
      st_idx.data.push_back(idx1);
      phi.data.push_back(e.perturbed ? e.pert_angle_rad * 180.0 / std::numbers::pi : std::nan(""));
    }
    if (e.kind == manip::trial_event_t::END) en_idx.data.push_back(idx1);
    if (e.kind == manip::trial_event_t::ONSET) on_idx.data.push_back(idx1);
  }
  st_idx.cols = st_idx.data.size();
  en_idx.cols = en_idx.data.size();
  on_idx.cols = on_idx.data.size();
  phi.rows = phi.data.size();
  const std::string data = o.dir + "/lab5.mat";
  ti::write_mat(data, MAT_FT_MAT5, {ti::MatVar{"note", 1, 1, {42.0}}}, "rec", {t, pos, frc, u, st_idx, en_idx, on_idx, phi});
  const std::string map = o.dir + "/lab-mat5.yaml";
  ti::write_text(map, "time: {variable: rec.t, unit: s}\n"
                      "signals:\n"
                      "  position: {variable: rec.pos, unit: m}\n"
                      "  handle_force: {variable: rec.force, columns: [2, 3], unit: N}\n"
                      "  perturbation_force: {variable: rec.u, unit: N}\n"
                      "frame:\n"
                      "  origin_in_shoulder_m: " + vec(o.rec.session.workspace_origin_in_shoulder_m) + "\n"
                      "trials:\n"
                      "  start: {variable: rec.start_idx, as: index}\n"
                      "  end: {variable: rec.end_idx, as: index}\n"
                      "  onset: {variable: rec.onset_idx, as: index}\n"
                      "  angle: {variable: rec.phi_deg, unit: deg}\n" +
                          session_yaml(o.rec.session));
  return {map, data};
}

// MAT v7.3: top-level variables, channels in rows (3 x N), force as two
// vectors, 0-based trial index with -1 between trials, sample rate only.
std::pair<std::string, std::string> export_mat73(const Original& o) {
  const std::size_t n = o.states.size();
  ti::MatVar x{"X", 3, n, std::vector<double>(3 * n)}, f1{"F1", n, 1, {}}, f2{"F2", 1, n, {}},
      u{"U", n, 2, std::vector<double>(2 * n)}, tr{"trial", n, 1, {}};
  for (std::size_t i = 0; i < n; ++i) {
    const auto& st = o.states[i];
    x.data[3 * i] = 0.0;  // (row 1: another channel)
    x.data[3 * i + 1] = st.x_workspace_m[0];
    x.data[3 * i + 2] = st.x_workspace_m[1];
    f1.data.push_back(st.f_sensor_workspace_n[0]);
    f2.data.push_back(st.f_sensor_workspace_n[1]);
    u.data[i] = st.u_pert_workspace_n[0];
    u.data[n + i] = st.u_pert_workspace_n[1];
    tr.data.push_back(st.trial);
  }
  const std::string data = o.dir + "/lab73.mat";
  ti::write_mat(data, MAT_FT_MAT73, {x, f1, f2, u, tr});
  const std::string map = o.dir + "/lab-mat73.yaml";
  ti::write_text(map, "time: {sample_rate_hz: 4000}\n"
                      "signals:\n"
                      "  position: {variable: X, columns: [2, 3], unit: m}\n"
                      "  handle_force: {variables: [F1, F2], unit: N}\n"
                      "  perturbation_force: {variable: U, unit: N}\n"
                      "frame:\n"
                      "  origin_in_shoulder_m: " + vec(o.rec.session.workspace_origin_in_shoulder_m) + "\n"
                      "trials:\n"
                      "  index: {variable: trial}\n"
                      "  onset: {rule: threshold, threshold_n: 0.5}\n" +
                          session_yaml(o.rec.session));
  return {map, data};
}

// The worked example of docs/import.md: config/import-example.yaml as shipped,
// on a MAT v7.3 file laid out as it describes (struct rec; pos in mm; a 6-axis
// force/torque sensor; 1-based trial numbers, 0 between trials). Its session
// constants are the simulator's defaults, so it must reproduce the original.
std::pair<std::string, std::string> export_example(const Original& o) {
  const std::size_t n = o.states.size();
  const auto c0 = o.states.front().cycle;
  ti::MatVar t{"t", n, 1, {}}, pos{"pos", n, 2, std::vector<double>(2 * n)}, frc{"F", n, 6, std::vector<double>(6 * n)},
      u{"u_pert", n, 2, std::vector<double>(2 * n)}, tr{"trial", n, 1, {}};
  for (std::size_t i = 0; i < n; ++i) {
    const auto& st = o.states[i];
    t.data.push_back(static_cast<double>(st.cycle - c0) / 4000.0);
    for (std::size_t a = 0; a < 2; ++a) {
      pos.data[a * n + i] = st.x_workspace_m[a] * 1000.0;
      frc.data[a * n + i] = st.f_sensor_workspace_n[a];
      u.data[a * n + i] = st.u_pert_workspace_n[a];
    }
    for (std::size_t a = 2; a < 6; ++a) frc.data[a * n + i] = 0.01 * static_cast<double>(a);  // Fz, torques
    tr.data.push_back(st.trial < 0 ? 0.0 : st.trial + 1.0);
  }
  const std::string data = o.dir + "/example73.mat";
  ti::write_mat(data, MAT_FT_MAT73, {}, "rec", {t, pos, frc, u, tr});
  return {std::string(MANIP_SOURCE_DIR) + "/config/import-example.yaml", data};
}

struct RoundTripCollector final : logging::SessionHandler {
  std::vector<manip::trial_event_t> events;
  std::int64_t states{0};
  manip::session_t session{};
  void on_session(const manip::session_t& m) override { session = m; }
  void on_state(const manip::state_t&) override { ++states; }
  void on_trial_event(const manip::trial_event_t& e) override { events.push_back(e); }
};

est::EstimatorSettings settings() {
  est::EstimatorSettings s;
  s.methods = {est::default_method(), "paper", "paper-pooled"};
  return s;
}

const est::Report& original_report() {
  static const est::Report r = est::estimate_log(original().log, settings());
  return r;
}

double max_abs(const Mat2& m) { return m.cwiseAbs().maxCoeff(); }

// Differences of D and K over every summary (session and per angle) and every
// per-trial fit, each element scored as |Δ| / max(kRel * (largest element of
// its matrix, at least 1), kSe * its own SE): <= 1 is agreement. Per-angle
// summaries of a single trial are that trial's fit again (compared there).
struct Diff {
  double score{0};
  std::string where;            // of the largest score
  double session_rel{0};        // largest relative difference of the session estimates
};
Diff compare(const est::Report& a, const est::Report& b, const std::string& label) {
  REQUIRE(a.n_used == b.n_used);
  REQUIRE(a.n_perturbed == b.n_perturbed);
  REQUIRE(a.summaries.size() == b.summaries.size());
  REQUIRE(a.trials.size() == b.trials.size());
  Diff w;
  auto rel = [](const Mat2& x, const Mat2& y) { return max_abs(x - y) / std::max(1.0, std::max(max_abs(x), max_abs(y))); };
  auto score = [&](const Mat2& x, const Mat2& y, const Mat2& se, const std::string& where) {
    const double scale = std::max(1.0, std::max(max_abs(x), max_abs(y)));
    for (int i = 0; i < 4; ++i) {
      const double d = std::abs(x(i) - y(i));
      const double s_i = std::isfinite(se(i)) ? se(i) : 0.0;
      const double r = d / std::max(kRel * scale, kSe * s_i);
      if (r > w.score) {
        w.score = r;
        w.where = where + " element " + std::to_string(i) + " (|diff| " + std::to_string(d) + ", SE " +
                  std::to_string(s_i) + ")";
      }
    }
  };
  for (std::size_t i = 0; i < a.summaries.size(); ++i) {
    const auto& sa = a.summaries[i];
    const auto& sb = b.summaries[i];
    REQUIRE(sa.method == sb.method);
    REQUIRE(sa.group == sb.group);
    REQUIRE(sa.n_trials == sb.n_trials);
    if (!sa.group.is_session() && sa.n_trials < 2 && sa.kind != "pooled fit") continue;
    score(sa.d_nspm, sb.d_nspm, sa.d_spread, sa.method + " " + sa.group.label() + " D");
    score(sa.k_npm, sb.k_npm, sa.k_spread, sa.method + " " + sa.group.label() + " K");
    if (sa.group.is_session()) {
      const double r = std::max(rel(sa.d_nspm, sb.d_nspm), rel(sa.k_npm, sb.k_npm));
      w.session_rel = std::max(w.session_rel, r);
      std::cout << "  " << label << " " << sa.method << " session: D11 " << sa.d_nspm(0, 0) << " vs " << sb.d_nspm(0, 0)
                << ", K22 " << sa.k_npm(1, 1) << " vs " << sb.k_npm(1, 1) << "; largest relative difference D "
                << rel(sa.d_nspm, sb.d_nspm) << ", K " << rel(sa.k_npm, sb.k_npm) << "\n";
    }
  }
  for (std::size_t i = 0; i < a.trials.size(); ++i) {
    const auto& ta = a.trials[i];
    const auto& tb = b.trials[i];
    REQUIRE(ta.trial == tb.trial);
    REQUIRE(ta.method == tb.method);
    score(ta.est.d_nspm, tb.est.d_nspm, ta.est.d_se, ta.method + " trial " + std::to_string(ta.trial) + " D");
    score(ta.est.k_npm, tb.est.k_npm, ta.est.k_se, ta.method + " trial " + std::to_string(ta.trial) + " K");
  }
  std::cout << "  " << label << ": worst score over all summaries and trials " << w.score << " at " << w.where << "\n";
  return w;
}

void check_layout(const std::string& label, const std::pair<std::string, std::string>& files, bool angle_exact) {
  const auto& o = original();
  const std::string out = o.dir + "/imported-" + label + ".lcm";
  const auto sum = importer::import_session(files.first, files.second, out, true);
  INFO(label);
  CHECK(sum.samples == static_cast<std::int64_t>(o.states.size()));
  CHECK(sum.sample_rate_hz == 4000.0);

  // Events: the same trials, the same START/ONSET/END cycles (the onset rule
  // recovers the simulator's onset cycle), the same angles.
  RoundTripCollector c;
  logging::read_log(out, c);
  CHECK(c.states == static_cast<std::int64_t>(o.states.size()));
  REQUIRE(c.events.size() == o.events.size());
  const auto c0 = o.states.front().cycle;
  for (std::size_t i = 0; i < o.events.size(); ++i) {
    INFO("event " << i);
    CHECK(c.events[i].kind == o.events[i].kind);
    CHECK(c.events[i].trial == o.events[i].trial);
    CHECK(c.events[i].cycle == o.events[i].cycle - c0);
    CHECK(c.events[i].perturbed == o.events[i].perturbed);
    if (o.events[i].perturbed) {
      if (angle_exact) CHECK(c.events[i].pert_angle_rad == o.events[i].pert_angle_rad);
      else CHECK(c.events[i].pert_angle_rad == Approx(o.events[i].pert_angle_rad).margin(1e-12));
    }
  }
  const auto imported = est::estimate_log(out, settings());
  const auto d = compare(original_report(), imported, label);
  CHECK(d.score <= 1.0);
}

}  // namespace

TEST_CASE("importer round trip: CSV in mm, lab frame rotated and mirrored, trial-index column") {
  check_layout("csv", export_csv(original()), true);
}

TEST_CASE("importer round trip: MAT v5 struct with marker indices and per-trial angles") {
  check_layout("mat5", export_mat5(original()), false);
}

TEST_CASE("importer round trip: MAT v7.3, channels in rows, sample rate only") {
  check_layout("mat73", export_mat73(original()), true);
}

TEST_CASE("importer round trip: the comparison is sensitive (one trial's onset one sample late exceeds the tolerance)") {
  auto rec = original().rec;
  for (auto& it : rec.items)
    if (it.kind == 1 && it.event.kind == manip::trial_event_t::ONSET) {
      it.event.cycle += 1;
      break;
    }
  const std::string path = original().dir + "/onset-shifted.lcm";
  testutil::write_recorded(rec, path);
  const auto shifted = est::estimate_log(path, settings());
  const auto d = compare(original_report(), shifted, "onset+1");
  CHECK(d.score > 10.0);
}

TEST_CASE("importer round trip: the worked example (config/import-example.yaml, MAT v7.3 struct)") {
  check_layout("example", export_example(original()), true);
}

TEST_CASE("importer round trip: the estimator's own floor (a few ulp on the original's samples)") {
  auto rec = original().rec;
  const double ulp4 = 4 * std::numeric_limits<double>::epsilon();
  for (auto& it : rec.items)
    if (it.kind == 0)
      for (int a = 0; a < 2; ++a) {
        it.state.x_workspace_m[a] *= 1 + ulp4;
        it.state.f_sensor_workspace_n[a] *= 1 - ulp4;
      }
  const std::string path = original().dir + "/ulp.lcm";
  testutil::write_recorded(rec, path);
  const auto d = compare(original_report(), est::estimate_log(path, settings()), "ulp");
  CHECK(d.score <= 1.0);
}
