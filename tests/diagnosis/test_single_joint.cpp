// The single-joint front end: CSV layout and its errors, the baseline's
// least squares and the reflex low pass against analytic solutions.
#include <catch2/catch.hpp>
#include <cmath>
#include <complex>
#include <fstream>
#include <numbers>

#include "diag_test_util.hpp"
#include "manip/common/errors.hpp"
#include "manip/diagnosis/mechanisms.hpp"

using namespace manip::diagnosis;

namespace {
std::string write(const std::string& name, const std::string& text) {
  const auto p = test::tmp_path(name);
  std::ofstream(p) << text;
  return p;
}
std::string error_of(const std::string& path) {
  try {
    (void)read_single_joint_csv(path);
  } catch (const manip::InputError& e) {
    CHECK(e.exit_code() == manip::exit_code::kInput);
    return e.what();
  }
  return "no error";
}
}  // namespace

TEST_CASE("CSV layouts: dt header with two columns, time column, named header", "[diagnosis][csv]") {
  const auto a = read_single_joint_csv(write("a.csv", "# dt=0.001; channels=['pos1', 'tq1']\n0.07,-2.7\n0.08,-2.6\n0.09,-2.5\n"));
  CHECK(a.dt_s == 0.001);
  REQUIRE(a.pos_rad.size() == 3);
  CHECK(a.pos_rad[1] == 0.08);
  CHECK(a.torque_nm[2] == -2.5);
  const auto b = read_single_joint_csv(write("b.csv", "0.000,1,2\n0.002,3,4\n0.004,5,6\n"));
  CHECK(b.dt_s == Approx(0.002));
  CHECK(b.torque_nm[1] == 4.0);
  const auto c = read_single_joint_csv(write("c.csv", "# lab X\ntorque_nm, time_s, pos_rad\n7,0.0,1\n8,0.01,2\n"));
  CHECK(c.dt_s == Approx(0.01));
  CHECK(c.pos_rad[1] == 2.0);
  CHECK(c.torque_nm[0] == 7.0);
}

TEST_CASE("CSV columns chosen by name: a channels= list in any order with extra channels, a header with extra columns", "[diagnosis][csv]") {
  // An export with EMG next to the two channels, and the torque first.
  const auto a = read_single_joint_csv(
      write("ch1.csv", "# dt=0.001; channels=['tq1', 'emgGS', 'pos1', 'emgTA']\n-2.7,0.3,0.07,x\n-2.6,0.2,0.08,y\n"));
  REQUIRE(a.pos_rad.size() == 2);
  CHECK(a.pos_rad[1] == 0.08);
  CHECK(a.torque_nm[0] == -2.7);
  CHECK(a.columns_note == "columns by name: position 'pos1' (3), torque 'tq1' (1); ignored 'emgGS' (2), 'emgTA' (4)");
  // Two channels in the default order: the default layout, no note.
  const auto b = read_single_joint_csv(write("ch2.csv", "# dt=0.001; channels=['pos1', 'tq1']\n0.07,-2.7\n0.08,-2.6\n"));
  CHECK(b.columns_note.empty());
  CHECK(b.torque_nm[1] == -2.6);
  // Names that say nothing fall back to the positional layout.
  const auto c = read_single_joint_csv(write("ch3.csv", "# dt=0.001; channels=['a', 'b']\n0.07,-2.7\n0.08,-2.6\n"));
  CHECK(c.pos_rad[0] == 0.07);
  CHECK(c.torque_nm[0] == -2.7);
  // A header line with an extra column: ignored and said.
  const auto d = read_single_joint_csv(write("ch4.csv", "time_s,emg_v,pos_rad,torque_nm\n0.0,1,0.1,5\n0.01,2,0.2,6\n"));
  CHECK(d.dt_s == Approx(0.01));
  CHECK(d.pos_rad[1] == 0.2);
  CHECK(d.columns_note.find("ignored 'emg_v' (2)") != std::string::npos);
  // Errors: wrong channel count, degrees, unresolvable extra columns.
  const auto e1 = write("ch5.csv", "# dt=0.001; channels=['pos1', 'tq1']\n0.07,-2.7,1\n");
  CHECK(error_of(e1) == e1 + ":2: \"channels=\" (line 1) names 2 channels, the data has 3 fields");
  const auto e2 = write("ch6.csv", "# dt=0.001; channels=['pos_deg', 'tq1']\n0.07,-2.7\n");
  CHECK(error_of(e2) == e2 + ":2: \"channels=\" (line 1): channel 'pos_deg' looks like degrees; the layout needs radians");
  const auto e3 = write("ch7.csv", "# dt=0.001; channels=['pos1', 'pos2', 'tq1', 'tq2']\n1,2,3,4\n");
  CHECK(error_of(e3).find(":2: expected 2 columns (pos_rad, torque_nm) or 3 (time_s, pos_rad, torque_nm), got 4 and "
                          "\"channels=\" names no single position and torque channel (pos1, pos2, tq1, tq2)") !=
        std::string::npos);
}

TEST_CASE("CSV errors name the file and the line", "[diagnosis][csv]") {
  const auto p1 = write("e1.csv", "# dt=0.001\n0.1,0.2\n0.1,abc\n");
  CHECK(error_of(p1) == p1 + ":3: field 2 is not a finite number (\"abc\")");
  const auto p2 = write("e2.csv", "# dt=0.001\n0.1,0.2\n0.1,0.2,0.3\n");
  CHECK(error_of(p2) == p2 + ":3: expected 2 fields, got 3");
  const auto p3 = write("e3.csv", "0.1,0.2\n0.1,0.2\n");
  CHECK(error_of(p3).find("sample period unknown") != std::string::npos);
  const auto p4 = write("e4.csv", "# dt=-1\n0.1,0.2\n");
  CHECK(error_of(p4).rfind(p4 + ":1: ", 0) == 0);
  const auto p5 = write("e5.csv", "0.0,1,2\n0.001,1,2\n0.003,1,2\n");
  CHECK(error_of(p5).find("not uniformly sampled") != std::string::npos);
  const auto p6 = write("e6.csv", "time_s,angle,torque_nm\n");
  CHECK(error_of(p6) == p6 + ":1: header must name pos_rad and torque_nm (columns: time_s, angle, torque_nm)");
  const auto p7 = write("e7.csv", "# dt=0.001\n0.1,nan\n");
  CHECK(error_of(p7) == p7 + ":2: field 2 is not a finite number (\"nan\")");
  CHECK(error_of(test::tmp_path("missing.csv")).find("cannot open") != std::string::npos);
}

TEST_CASE("baseline least squares recovers I, B, K, c of a noise-free record exactly", "[diagnosis][baseline]") {
  // x = sum of sines (analytic derivatives); torque = I x'' + B x' + K (x - mean) + c
  // recorded as the reaction (negated): the front end must flip it back.
  SingleJointRecord r;
  r.source = "analytic";
  r.dt_s = 0.001;
  const double I = 0.02, B = 0.9, K = 150.0, c = 3.0;
  const int n = 20000;
  std::vector<double> x(n), xd(n), xdd(n);
  for (int i = 0; i < n; ++i) {
    const double t = i * r.dt_s;
    x[static_cast<std::size_t>(i)] = 0.02 * std::sin(2 * std::numbers::pi * 1.3 * t) + 0.01 * std::sin(2 * std::numbers::pi * 4.1 * t + 1.0);
    xd[static_cast<std::size_t>(i)] = 0.02 * 2 * std::numbers::pi * 1.3 * std::cos(2 * std::numbers::pi * 1.3 * t) +
                                      0.01 * 2 * std::numbers::pi * 4.1 * std::cos(2 * std::numbers::pi * 4.1 * t + 1.0);
    xdd[static_cast<std::size_t>(i)] = -0.02 * std::pow(2 * std::numbers::pi * 1.3, 2) * std::sin(2 * std::numbers::pi * 1.3 * t) -
                                       0.01 * std::pow(2 * std::numbers::pi * 4.1, 2) * std::sin(2 * std::numbers::pi * 4.1 * t + 1.0);
  }
  r.pos_rad = x;
  r.torque_nm.resize(n);
  const auto prep0 = prepare_single_joint(r);  // to learn x_ref (mean over the usable range)
  const double ref = prep0.data.pos_ref;
  for (std::size_t i = 0; i < x.size(); ++i) r.torque_nm[i] = -(I * xdd[i] + B * xd[i] + K * (x[i] - ref) + c);
  const auto prep = prepare_single_joint(r);
  CHECK(prep.torque_sign == -1);
  CHECK(prep.sign_flipped_automatically);
  const auto f = fit_full(prep.data, {});
  // Not bit-exact: the order-5 Savitzky-Golay derivatives of a sine differ from
  // the smoothed true derivatives by ~1e-4 (relative) at 4 Hz with a 43-sample
  // window; the elastic term, from deriv 0, is far more exact.
  CHECK(f.theta(0) == Approx(I).epsilon(5e-4));
  CHECK(f.theta(1) == Approx(B).epsilon(5e-4));
  CHECK(f.theta(2) == Approx(K).epsilon(1e-5));
  CHECK(f.theta(3) == Approx(c).epsilon(1e-5));
  CHECK(f.sse < 1e-6 * f.sst);
  // The Savitzky-Golay window comes from the cut-off: nearest -3 dB point to 40 Hz at 1 kHz.
  CHECK(prep.cutoff_hz == Approx(40.0).margin(1.0));
}

TEST_CASE("reflex column at 100 Hz: a delay between samples (43 ms) against the analytic steady state, whole samples would be 3 ms off", "[diagnosis][mechanisms]") {
  // Velocity 1 + 0.5 sin(w t) > 0: the stretch direction's rectifier passes
  // it unchanged, and the column in steady state is
  //   H(0) + 0.5 |H(w)| sin(w (t - delay) + arg H(w)),
  // H the reflex low pass evaluated on the unit circle from its coefficients.
  const double dt = 0.01, f = 2.0, w = 2.0 * std::numbers::pi * f, fn = 5.0, zeta = 0.75, delay = 0.043;
  const auto prep = test::prepared_position(dt, 3000, [&](double t) { return t + 0.5 / w * (1.0 - std::cos(w * t)); });
  const auto lib = standard_library();
  const Mechanism* reflex = test::mechanism_by_id(lib, "stretch_reflex");
  REQUIRE(reflex);
  const auto c = reflex_lowpass_sos(fn, zeta, dt);
  const std::complex<double> zi = std::exp(std::complex<double>(0, -w * dt));
  const auto H = (c[0] + c[1] * zi + c[2] * zi * zi) / (c[3] + c[4] * zi + c[5] * zi * zi);
  const double H0 = (c[0] + c[1] + c[2]) / (c[3] + c[4] + c[5]);
  auto worst = [&](double d_s) {
    const std::vector<double> setting{d_s, fn, zeta};
    const auto cols = reflex->columns(prep.data, setting);
    const auto& g = prep.data.segments.front();
    double e = 0.0;
    for (std::size_t i = g.first + 500; i < g.last; ++i) {  // after 5 s: the low pass's transient is gone
      const double t = g.t0_s + static_cast<double>(i) * dt;
      const double ref = H0 + 0.5 * std::abs(H) * std::sin(w * (t - delay) + std::arg(H));
      e = std::max(e, std::fabs(cols.front()[0][i] - ref));
    }
    return e;
  };
  // Linear interpolation's error bound, (w dt)^2 / 8 of the 0.5 |H| amplitude, plus the smoother's gain at 2 Hz.
  CHECK(worst(delay) < 2e-3);
  CHECK(worst(0.040) > 1e-2);
  CHECK(worst(0.050) > 1e-2);
}

TEST_CASE("stiffness relaxation column: a sinusoid through tau s / (1 + tau s) against the continuous steady state", "[diagnosis][mechanisms]") {
  // x = A sin(w t) about x_ref: the column x_c - LP_tau[x_c] is, in steady
  // state, A |G| sin(w t + arg G) with G = j w tau / (1 + j w tau). The
  // recursion's discretisation error is O(dt / tau); its transient from the
  // start (the low pass starts at the first sample) has decayed after 10 tau.
  const double dt = 0.001, A = 0.02, f = 0.3, w = 2.0 * std::numbers::pi * f;
  const auto prep = test::prepared_position(dt, 40000, [&](double t) { return A * std::sin(w * t); });
  const auto lib = standard_library();
  const Mechanism* relax = test::mechanism_by_id(lib, "stiffness_relaxation");
  REQUIRE(relax);
  for (const double tau : {0.2, 1.0, 2.0}) {
    const std::vector<double> setting{tau};
    const auto cols = relax->columns(prep.data, setting);
    const auto& g = prep.data.segments.front();
    const std::complex<double> G = std::complex<double>(0, w * tau) / (1.0 + std::complex<double>(0, w * tau));
    double e = 0.0;
    for (std::size_t i = static_cast<std::size_t>(10.0 * tau / dt); i < g.last; ++i) {
      const double t = static_cast<double>(i) * dt;
      const double ref = A * std::abs(G) * std::sin(w * t + std::arg(G));
      e = std::max(e, std::fabs(cols.front()[0][i] - ref));
    }
    INFO("tau " << tau << " worst " << e << " of amplitude " << A * std::abs(G));
    CHECK(e < 0.01 * A * std::abs(G) + 1e-6);
  }
}

TEST_CASE("reflex low pass: unit DC gain and |H(fn)| = 1 / (2 zeta) (prewarped bilinear)", "[diagnosis][mechanisms]") {
  for (double fn : {1.0, 4.0, 20.0})
    for (double z : {0.5, 0.75, 1.0}) {
      const auto c = reflex_lowpass_sos(fn, z, 0.001);
      auto H = [&](double f) {
        const std::complex<double> zi = std::exp(std::complex<double>(0, -2 * std::numbers::pi * f * 0.001));
        return (c[0] + c[1] * zi + c[2] * zi * zi) / (c[3] + c[4] * zi + c[5] * zi * zi);
      };
      // (b0 + b1 + b2) / (1 + a1 + a2) cancels ~1e-6-sized sums at fn = 1 Hz, fs = 1 kHz
      CHECK(std::abs(H(0.0)) == Approx(1.0).epsilon(1e-8));
      CHECK(std::abs(H(fn)) == Approx(1.0 / (2.0 * z)).epsilon(1e-9));
    }
}
