// The mapping and the data, checked: a small hand-made recording (1 kHz, two
// trials, one perturbation whose onset and direction are known by
// construction) imports to exactly what was put in, and every kind of
// mistake a lab makes in a mapping is refused with a message that names the
// mapping's file, line and key and the data file and variable.
#include <catch2/catch.hpp>

#include <cmath>
#include <filesystem>
#include <functional>
#include <numbers>
#include <sstream>

#include "fixtures.hpp"
#include "import_test_util.hpp"
#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/importer/convert.hpp"
#include "manip/logging/session_stream.hpp"

using namespace manip;
namespace ti = manip::test_import;

namespace {

constexpr std::size_t kN = 4000;         // samples at 1 kHz
constexpr std::size_t kOnset = 3000;     // last zero-force sample before the push (manip's ONSET cycle)
constexpr double kPushDeg = 120.0;       // push direction, shoulder frame

const char* kSession =
    "session:\n"
    "  participant_id: P01\n"
    "  session_id: S1\n"
    "  admittance: {m_adm_kg: [5, 5], d_adm_nspm: [15, 15]}\n"
    "  m_handle_kg: [0.25, 0.25]\n"
    "  anthropometrics:\n"
    "    segment_length_m: [0.31, 0.34]\n"
    "    segment_mass_kg: [1.93, 1.52]\n"
    "    segment_com_m: [0.165, 0.19]\n"
    "    segment_inertia_kgm2: [0.0141, 0.0188]\n"
    "  perturbation: {duration_s: 0.15, amplitude_n: 15, trigger_x2_shoulder_m: 0.40}\n";

// Line numbers below are part of the tests (messages must name them).
std::string mapping(const std::string& line1 = "time: {variable: t, unit: s}",
                    const std::string& line3 = "  position: {variables: [x_mm, y_mm], unit: mm}",
                    const std::string& line11 = "  index: {variable: trial, outside: -1}") {
  return line1 + "\n" +                                              // 1
         "signals:\n" +                                               // 2
         line3 + "\n" +                                               // 3
         "  handle_force: {variables: [fx, fy], unit: N}\n"           // 4
         "  perturbation_force: {variables: [ux, uy], unit: N}\n"     // 5
         "frame:\n"                                                   // 6
         "  axes: [2, -1]\n"                                          // 7
         "  origin_in_shoulder_m: [0.0, 0.425]\n"                     // 8
         "  rotation_deg: 0\n"                                        // 9
         "trials:\n"                                                  // 10
         + line11 + "\n" +                                            // 11
         "  onset: {rule: threshold, threshold_n: 0.5}\n" +           // 12
         kSession;
}

// Recorded components: workspace = (rec2, -rec1) by axes [2, -1].
struct Row {
  double t, x_mm, y_mm, fx, fy, ux, uy, trial;
};
std::vector<Row> rows() {
  std::vector<Row> r(kN);
  const double ws_dir[2] = {std::cos(kPushDeg * std::numbers::pi / 180), std::sin(kPushDeg * std::numbers::pi / 180)};
  for (std::size_t i = 0; i < kN; ++i) {
    const double t = static_cast<double>(i) / 1000.0;
    double u = 0.0;
    if (i >= kOnset && i <= kOnset + 150) {
      const double s = std::sin(std::numbers::pi * static_cast<double>(i - kOnset) / 150.0);
      u = 15.0 * s * s;
    }
    // ws = u * dir  ->  rec1 = -ws2, rec2 = ws1
    const double trial = (i >= 500 && i < 2000) ? 0 : (i >= 2200 && i < 3800) ? 1 : -1;
    r[i] = Row{t, 100.0 + 10.0 * std::sin(t), -50.0 + 80.0 * t, 0.1 * t, -0.2, -u * ws_dir[1], u * ws_dir[0], trial};
  }
  return r;
}

std::string csv_text(const std::vector<Row>& r) {
  std::ostringstream o;
  o.precision(17);
  o << "t,x_mm,y_mm,fx,fy,ux,uy,trial\n";
  for (const auto& x : r)
    o << x.t << "," << x.x_mm << "," << x.y_mm << "," << x.fx << "," << x.fy << "," << x.ux << "," << x.uy << ","
      << x.trial << "\n";
  return o.str();
}

struct Files {
  std::string dir, map, data, out;
};
Files files(const std::string& name, const std::string& map_text, const std::string& csv) {
  Files f;
  f.dir = testutil::temp_dir("importer_" + name);
  f.map = f.dir + "/map.yaml";
  f.data = f.dir + "/data.csv";
  f.out = f.dir + "/out.lcm";
  ti::write_text(f.map, map_text);
  if (!csv.empty()) ti::write_text(f.data, csv);
  return f;
}

// Runs the import, expects an error of type E whose message holds every
// piece, and that nothing was left at the output path.
template <class E>
void expect_error(const Files& f, const std::vector<std::string>& pieces, int code) {
  bool thrown = false;
  try {
    importer::import_session(f.map, f.data, f.out, false);
  } catch (const E& e) {
    thrown = true;
    const std::string msg = e.what();
    INFO("message: " << msg);
    for (const auto& p : pieces) CHECK(msg.find(p) != std::string::npos);
    CHECK(e.exit_code() == code);
  }
  CHECK(thrown);
  CHECK_FALSE(std::filesystem::exists(f.out));
  for (const auto& entry : std::filesystem::directory_iterator(f.dir))
    CHECK(entry.path().filename().string().find(".partial-") == std::string::npos);
}

struct Collector final : logging::SessionHandler {
  manip::session_t session{};
  std::vector<manip::state_t> states;
  std::vector<manip::trial_event_t> events;
  void on_session(const manip::session_t& m) override { session = m; }
  void on_state(const manip::state_t& s) override { states.push_back(s); }
  void on_trial_event(const manip::trial_event_t& e) override { events.push_back(e); }
};

}  // namespace

TEST_CASE("importer: a hand-made recording imports to what was put in") {
  const auto f = files("valid", mapping(), csv_text(rows()));
  const auto sum = importer::import_session(f.map, f.data, f.out, false);
  CHECK(sum.samples == static_cast<std::int64_t>(kN));
  CHECK(sum.sample_rate_hz == 1000.0);
  CHECK(sum.trials == 2);
  CHECK(sum.perturbed == 1);
  CHECK(sum.notes.empty());
  {  // the frame check printed by manip_import: workspace (y, -x) mm -> m, + origin (0, 0.425)
    const auto r = rows();
    const double sx = 0.5 * (r[500].y_mm + r[2200].y_mm) / 1000.0;
    const double sy = 0.5 * (-r[500].x_mm - r[2200].x_mm) / 1000.0 + 0.425;
    CHECK(sum.mean_start_shoulder_m(0) == Approx(sx).epsilon(1e-12));
    CHECK(sum.mean_start_shoulder_m(1) == Approx(sy).epsilon(1e-12));
    const double ex = 0.5 * (r[1999].y_mm + r[3799].y_mm) / 1000.0;
    CHECK(sum.mean_end_shoulder_m(0) == Approx(ex).epsilon(1e-12));
  }
  Collector c;
  logging::read_log(f.out, c);
  CHECK(c.session.sample_rate_hz == 1000.0);
  CHECK(c.session.participant_id == "P01");
  CHECK(c.session.m_adm_kg[0] == 5.0);
  CHECK(c.session.workspace_origin_in_shoulder_m[1] == 0.425);
  REQUIRE(c.states.size() == kN);
  // Sample 0: x_mm = 100, y_mm = -50 -> workspace (y, -x) in m.
  CHECK(c.states[0].x_workspace_m[0] == Approx(-0.050).epsilon(1e-15));
  CHECK(c.states[0].x_workspace_m[1] == Approx(-0.100).epsilon(1e-15));
  CHECK(c.states[0].trial == -1);
  CHECK(c.states[600].trial == 0);
  CHECK(c.states[2100].trial == -1);
  CHECK(c.states[2200].trial == 1);
  CHECK(c.states[2200].utime == 2200000);  // us from the recording's first sample
  CHECK(std::isnan(c.states[10].xd_workspace_mps[0]));  // not recorded: documented NaN
  CHECK(std::isnan(c.states[10].f_motor_n[1]));
  CHECK(c.states[kOnset + 10].phase == manip::state_t::PHASE_PERTURBATION);
  CHECK(c.states[kOnset + 200].phase == manip::state_t::PHASE_REACH);
  CHECK(c.states[2100].phase == manip::state_t::PHASE_RETURN);
  // Events: START 500, END 1999; START 2200, ONSET 3000, END 3799.
  REQUIRE(c.events.size() == 5);
  CHECK(c.events[0].kind == manip::trial_event_t::START);
  CHECK(c.events[0].cycle == 500);
  CHECK_FALSE(c.events[0].perturbed);
  CHECK(c.events[1].kind == manip::trial_event_t::END);
  CHECK(c.events[1].cycle == 1999);
  CHECK(c.events[2].cycle == 2200);
  CHECK(c.events[2].perturbed);
  CHECK(c.events[3].kind == manip::trial_event_t::ONSET);
  CHECK(c.events[3].cycle == static_cast<std::int64_t>(kOnset));
  CHECK(c.events[3].pert_angle_rad == Approx(kPushDeg * std::numbers::pi / 180).epsilon(1e-15));
  CHECK(c.events[4].kind == manip::trial_event_t::END);
  CHECK(c.events[4].cycle == 3799);
  // Never clobbers without force; with force it replaces.
  CHECK_THROWS_AS(importer::import_session(f.map, f.data, f.out, false), OutputError);
  CHECK_NOTHROW(importer::import_session(f.map, f.data, f.out, true));
}

TEST_CASE("importer: an unknown key is refused, naming the file, line and key") {
  const auto f = files("unknown_key", mapping("time: {variable: t, unit: s, offset: 3}"), csv_text(rows()));
  expect_error<ConfigError>(f, {f.map + ":1: time.offset: unknown key"}, exit_code::kConfig);
}

TEST_CASE("importer: a key given twice is refused") {
  const auto f = files("duplicate_key", mapping("time: {variable: t, unit: s, unit: ms}"), csv_text(rows()));
  expect_error<ConfigError>(f, {f.map + ":1: time.unit: duplicate key"}, exit_code::kConfig);
}

TEST_CASE("importer: a missing variable is named with the key and what the file holds") {
  const auto f = files("missing_variable", mapping("time: {variable: t, unit: s}", "  position: {variables: [x_mm, z_mm], unit: mm}"),
                       csv_text(rows()));
  expect_error<ConfigError>(f, {f.map + ":3: signals.position: variable 'z_mm' not found in " + f.data, "it holds: t, x_mm, y_mm, fx"},
                            exit_code::kConfig);
}

TEST_CASE("importer: an unknown unit is refused with the known ones") {
  const auto f = files("unknown_unit", mapping("time: {variable: t, unit: s}", "  position: {variables: [x_mm, y_mm], unit: inch}"),
                       csv_text(rows()));
  expect_error<ConfigError>(f, {f.map + ":3: signals.position.unit: unknown unit 'inch'", "known: m, cm, mm, um"},
                            exit_code::kConfig);
}

TEST_CASE("importer: time that does not increase is refused, naming the variable, key and sample") {
  auto r = rows();
  r[1234].t = r[1233].t;  // a repeated time stamp (sample 1235, 1-based)
  const auto f = files("time_not_increasing", mapping(), csv_text(r));
  expect_error<InputError>(f, {f.data + ": variable 't' (" + f.map + ":1: time.variable)", "does not increase at sample 1235"},
                           exit_code::kInput);
}

TEST_CASE("importer: a gap in the time base is refused") {
  auto r = rows();
  for (std::size_t i = 2000; i < kN; ++i) r[i].t += 0.005;  // five samples lost
  const auto f = files("time_gap", mapping(), csv_text(r));
  expect_error<InputError>(f, {f.data + ": variable 't'", "time.variable", "sample 2001", "max_jitter"}, exit_code::kInput);
}

TEST_CASE("importer: a variable of the wrong size is named with its size and the expected one") {
  const auto r = rows();
  // MAT v5: pos is (N-1) x 2; everything else right.
  ti::MatVar t{"t", kN, 1, {}}, pos{"pos", kN - 1, 2, {}}, f{"f", kN, 2, {}}, u{"u", kN, 2, {}}, tr{"trial", kN, 1, {}};
  for (std::size_t c = 0; c < 2; ++c)
    for (std::size_t i = 0; i < kN; ++i) {
      if (c == 0) {
        t.data.push_back(r[i].t);
        tr.data.push_back(r[i].trial);
      }
      if (i + 1 < kN) pos.data.push_back(c == 0 ? r[i].x_mm : r[i].y_mm);
      f.data.push_back(c == 0 ? r[i].fx : r[i].fy);
      u.data.push_back(c == 0 ? r[i].ux : r[i].uy);
    }
  auto fl = files("wrong_size", mapping("time: {variable: t, unit: s}", "  position: {variable: pos, unit: mm}"), "");
  fl.data = fl.dir + "/data.mat";
  ti::write_mat(fl.data, MAT_FT_MAT5, {t, pos, f, u, tr});
  // (the mapping's force lines name fx/fy and ux/uy, so fix them up to this file's names)
  auto text = mapping("time: {variable: t, unit: s}", "  position: {variable: pos, unit: mm}");
  text.replace(text.find("{variables: [fx, fy]"), std::string("{variables: [fx, fy]").size(), "{variable: f");
  text.replace(text.find("{variables: [ux, uy]"), std::string("{variables: [ux, uy]").size(), "{variable: u");
  ti::write_text(fl.map, text);
  expect_error<ConfigError>(fl, {fl.map + ":3: signals.position: variable 'pos' in " + fl.data + " is 3999 x 2",
                                 "expected 4000 x k with k >= 2", "time variable 't'"},
                            exit_code::kConfig);
}

TEST_CASE("importer: a variable that is not numeric is named as what it is") {
  auto fl = files("not_numeric", mapping("time: {variable: t, unit: s}", "  position: {variable: rec.pos, unit: mm}"), "");
  fl.data = fl.dir + "/data.mat";
  {  // a char array where the mapping expects the position matrix
    mat_t* mat = Mat_CreateVer(fl.data.c_str(), nullptr, MAT_FT_MAT5);
    REQUIRE(mat != nullptr);
    std::size_t dims[2] = {1, 5};
    char text[] = "hello";
    matvar_t* v = Mat_VarCreate("pos", MAT_C_CHAR, MAT_T_UINT8, 2, dims, text, 0);
    REQUIRE(Mat_VarWrite(mat, v, MAT_COMPRESSION_NONE) == 0);
    Mat_VarFree(v);
    Mat_Close(mat);
  }
  ti::write_text(fl.map, mapping("time: {sample_rate_hz: 1000}", "  position: {variable: pos, unit: mm}"));
  expect_error<ConfigError>(fl, {fl.map + ":3: signals.position: variable 'pos' in " + fl.data + " is a char array"},
                            exit_code::kConfig);
}

TEST_CASE("importer: markers that do not pair up are refused, naming both keys") {
  auto r = rows();
  std::ostringstream o;
  o.precision(17);
  o << "t,x_mm,y_mm,fx,fy,ux,uy,go,stop\n";
  for (std::size_t i = 0; i < kN; ++i)
    o << r[i].t << "," << r[i].x_mm << "," << r[i].y_mm << "," << r[i].fx << "," << r[i].fy << "," << r[i].ux << ","
      << r[i].uy << "," << (i == 500 || i == 2200 ? 1 : 0) << "," << (i == 1999 ? 1 : 0) << "\n";
  const auto f = files("markers", mapping("time: {variable: t, unit: s}", "  position: {variables: [x_mm, y_mm], unit: mm}",
                                          "  start: {variable: go}\n  end: {variable: stop}"),
                       o.str());
  expect_error<InputError>(f, {f.data + ": 2 trial starts (variable 'go', " + f.map + ":11: trials.start)",
                               "1 trial ends (variable 'stop', " + f.map + ":12: trials.end)"},
                           exit_code::kInput);
}

TEST_CASE("importer: unreadable inputs are named") {
  auto f = files("bad_input", mapping(), "");
  f.data = f.dir + "/data.mat";
  ti::write_text(f.data, "this is not a MAT file, just text that is long enough to have a header............"
                         ".......................................................................................");
  expect_error<InputError>(f, {f.data + ": not a MAT file"}, exit_code::kInput);
  f.data = f.dir + "/data.xlsx";
  ti::write_text(f.data, "x");
  expect_error<InputError>(f, {f.data + ": unknown input type '.xlsx'"}, exit_code::kInput);
  f.data = f.dir + "/bad.csv";
  ti::write_text(f.data, "t,x\n0,1\n0.001,abc\n");
  expect_error<InputError>(f, {f.data + ":3: column 'x': not a number ('abc')"}, exit_code::kInput);
}

TEST_CASE("importer: the MAT reader converts every numeric class and 1x1 structs") {
  const auto dir = testutil::temp_dir("importer_mat_classes");
  for (const auto ver : {MAT_FT_MAT5, MAT_FT_MAT73}) {
    const std::string path = dir + (ver == MAT_FT_MAT5 ? "/v5.mat" : "/v73.mat");
    std::remove(path.c_str());
    mat_t* mat = Mat_CreateVer(path.c_str(), nullptr, ver);
    REQUIRE(mat != nullptr);
    std::size_t dims[2] = {2, 3};
    std::int16_t i16[6] = {-3, 1, 4, -1, 5, -9};  // column-major: [[-3, 4, 5], [1, -1, -9]]
    float f32[6] = {0.5f, 1.5f, 2.5f, 3.5f, 4.5f, 5.5f};
    matvar_t* a = Mat_VarCreate("a", MAT_C_INT16, MAT_T_INT16, 2, dims, i16, 0);
    matvar_t* b = Mat_VarCreate("b", MAT_C_SINGLE, MAT_T_SINGLE, 2, dims, f32, 0);
    REQUIRE(Mat_VarWrite(mat, a, MAT_COMPRESSION_NONE) == 0);
    REQUIRE(Mat_VarWrite(mat, b, MAT_COMPRESSION_NONE) == 0);
    Mat_VarFree(a);
    Mat_VarFree(b);
    Mat_Close(mat);
    ti::write_mat(path + ".s.mat", ver, {}, "s", {ti::MatVar{"x", 1, 2, {7.0, 8.0}}});
    const auto ds = importer::read_dataset(path);
    CHECK(ds.format == (ver == MAT_FT_MAT5 ? "MAT v5" : "MAT v7.3"));
    const auto* va = ds.find("a");
    REQUIRE(va != nullptr);
    CHECK(va->rows == 2);
    CHECK(va->cols == 3);
    CHECK(va->at(0, 1) == 4.0);
    CHECK(va->at(1, 2) == -9.0);
    const auto* vb = ds.find("b");
    REQUIRE(vb != nullptr);
    CHECK(vb->at(1, 1) == 3.5);
    const auto ds2 = importer::read_dataset(path + ".s.mat");
    const auto* x = ds2.find("s.x");
    REQUIRE(x != nullptr);
    CHECK(x->cols == 2);
    CHECK(x->at(0, 1) == 8.0);
  }
}

TEST_CASE("importer: the example mappings in config/ are valid") {
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator(std::string(MANIP_SOURCE_DIR) + "/config")) {
    const auto name = e.path().filename().string();
    if (name.rfind("import-", 0) != 0 || e.path().extension() != ".yaml") continue;
    INFO(name);
    CHECK_NOTHROW(importer::load_mapping(e.path().string()));
    ++n;
  }
  CHECK(n >= 2);
}

TEST_CASE("importer: non-finite samples inside a trial are imported and reported") {
  auto r = rows();
  r[700].fx = std::nan("");  // trial 0 (samples 500..1999)
  r[100].x_mm = std::nan("");  // between trials: harmless
  const auto f = files("nonfinite", mapping(), csv_text(r));
  const auto sum = importer::import_session(f.map, f.data, f.out, false);
  REQUIRE(sum.notes.size() == 1);
  CHECK(sum.notes[0].find("trial 0: 1 samples with a non-finite position or force (first at sample 701)") != std::string::npos);
}
