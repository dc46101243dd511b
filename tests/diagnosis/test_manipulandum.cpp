// The manipulandum front end of diagnose_model (docs/diagnosis.md,
// "Manipulandum sessions"): sessions with one hidden mechanism, written by the
// simulation into the diagnosis' message handler exactly as into a log (the
// truth channels are dropped by LogCollector, so the diagnosis sees what a
// lab log shows); the truth for the checks comes from the generator.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <numbers>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>

#include "manip/common/errors.hpp"
#include "hidden_case.hpp"
#include "manip/diagnosis/likelihood_stage.hpp"
#include "manip/diagnosis/manipulandum.hpp"
#include "manip/diagnosis/report.hpp"
#include "manip/dsp/butterworth.hpp"
#include "manip/dsp/integrate.hpp"
#include "manip/dsp/savgol.hpp"
#include "manip/dsp/sosfilt.hpp"
#include "manip/estimation/output_error.hpp"
#include "manip/sim/hidden_effects.hpp"
#include "manip/sim/presets.hpp"

using namespace manip;
using namespace manip::diagnosis;
using namespace manip::diagnosis::testing;
using Eigen::Matrix2d;

namespace {
// The gain that carries the hidden mechanism's magnitude, its true value, and
// the session's detection limit for it (round 1, engine.hpp CandidateScore).
struct Limit {
  double truth = NAN, limit = NAN;
};
Limit limit_of(const Outcome& o, const sim::HiddenEffect& e) {
  const auto mp = main_param_of(e, o.draw, 4000.0);
  const std::string id = mp.id;
  std::string gain = mp.param;
  Limit l;
  l.truth = mp.truth;
  if (separates_feedback(e)) {  // its main parameter is a shape (the delay); the limit is on its gain
    gain = "gain_apparent";                             // relative to the apparent D, K ≈ (1 + g) × intrinsic
    l.truth = e.magnitude / (1.0 + e.magnitude);
  }
  if (o.dg.rounds.empty()) return l;
  for (const auto& c : o.dg.rounds.front().candidates) {
    if (c.id != id || c.gain_mde.empty()) continue;
    const std::size_t ns = c.params.size() - c.gain_mde.size();
    for (std::size_t k = 0; k < c.gain_mde.size(); ++k)
      if (c.params[ns + k].name == gain) l.limit = c.gain_mde[k];
  }
  return l;
}

}  // namespace

// The amplitude profile on analytic NLL curves (no fits: the evaluation
// returns the curve's value as the fit's likelihood).
namespace {
PemBaseline nll_point(double v) {
  PemBaseline b;
  b.available = b.has_likelihood = true;
  b.neg_log_likelihood = v;
  return b;
}
}  // namespace

TEST_CASE("manipulandum: the amplitude profile finds a parabola's minimum in one step, as before") {
  // NLL = 100 + 40 (α − 0.7)²: the parabola through α = 0, 1, 2 is the curve.
  const auto pr = profile_amplitude([](double a) { return nll_point(100.0 + 40.0 * (a - 0.7) * (a - 0.7)); }, nll_point(100.0 + 40.0 * 0.49));
  CHECK(pr.alpha == Approx(0.7).margin(1e-9));
  CHECK(pr.evaluations == 3);  // α = 1, 2, the vertex; the second step finds it seen
  // 2 ΔNLL ≤ χ²₁(0.95) = 3.841458820694124 (scipy.stats.chi2.ppf(0.95, 1)): α ± √(3.8415 / 80)
  CHECK(pr.half_width == Approx(std::sqrt(3.841458820694124 / 80.0)).epsilon(1e-6));
}

TEST_CASE("manipulandum: the amplitude profile steps past a concave start to the minimum beyond") {
  // NLL = α⁴/4 − 0.8 α³: NLL' = α² (α − 2.4), minimum at α = 2.4; concave on
  // (0, 1.6), so α = 0, 1, 2 (0, −0.55, −2.4) bend the wrong way and their
  // parabola's vertex is a maximum. The delayed copies' profiles look like
  // this (docs/diagnosis.md, "Direction-dependent reflex"); the profile used
  // to stop at α = 2.
  auto f = [](double a) { return a * a * a * a / 4.0 - 0.8 * a * a * a; };
  const auto pr = profile_amplitude([&](double a) { return nll_point(f(a)); }, nll_point(f(0.0)), 0.0);
  INFO("alpha " << pr.alpha << " after " << pr.evaluations << " evaluations");
  CHECK(pr.alpha == Approx(2.4).margin(0.1));
  CHECK(pr.fit.neg_log_likelihood < f(2.0) - 0.3);  // f(2) = −2.4, f(2.4) = −2.765
  CHECK(pr.evaluations <= 5);
}

TEST_CASE("manipulandum: the amplitude profile looks between the best and a wall the three best do not bracket") {
  // NLL = −10 α + 60 max(0, α − 2.3)²: minimum at α = 2.3 + 10/120 = 2.383;
  // the wall past it puts α = 3 last, so the three best (2, 1.84, 1) lie on
  // one side: their parabola steps away from the minimum, as the delayed
  // copies' profiles did (docs/diagnosis.md, "Amplitude profile"). After the
  // parabolic step that does not lower the NLL, a golden step into [2, 3].
  auto f = [](double a) { return -10.0 * a + 60.0 * std::pow(std::max(0.0, a - 2.3), 2); };
  const auto pr = profile_amplitude([&](double a) { return nll_point(f(a)); }, nll_point(f(0.0)));
  INFO("alpha " << pr.alpha << " after " << pr.evaluations << " evaluations");
  CHECK(pr.alpha == Approx(2.383).margin(0.05));
  CHECK(pr.evaluations <= 5);
}

TEST_CASE("manipulandum: the amplitude profile of an interior best costs no more than its two steps") {
  // NLL = 100 |α − 0.1|: a kink (as a loosely converged noise-free fit gives),
  // the best (α = 0) inside the profiled range after α = 1 and −1.
  auto f = [](double a) { return 100.0 * std::fabs(a - 0.1); };
  const auto pr = profile_amplitude([&](double a) { return nll_point(f(a)); }, nll_point(f(0.0)));
  CHECK(pr.evaluations <= 4);
  CHECK(std::fabs(pr.alpha - 0.1) < 0.1);
}

TEST_CASE("manipulandum: configuration_difference names the first differing field") {
  estimation::SessionInfo a, b;
  CHECK(configuration_difference(a, b).empty());
  b.m_handle_kg.y() = 0.3;
  CHECK(configuration_difference(a, b) == "m_handle_kg[1]: 0.25 vs 0.3");
  b = a;
  b.anthropometrics.mass_kg[0] = 2.5;
  CHECK(configuration_difference(a, b).rfind("anthropometrics.mass_kg[0]", 0) == 0);
}

TEST_CASE("manipulandum: too few perturbed trials for the cross-validation -> one message saying how many are needed") {
  sim::SessionDesign base;
  base.n_movements = 12;
  base.reps_per_angle = 1;
  auto person = sim::table1_person();
  auto hs = sim::make_hidden_session(base, person, {}, 1);
  std::vector<CollectedSession> ses(1);
  ses[0].name = "short.lcm";
  LogCollector col(ses[0]);
  const auto sum = sim::run_session(hs.design, *hs.person, col);
  col.finish();
  REQUIRE(sum.perturbed < 10);
  PlanarOptions po;
  po.pem_baseline = false;
  try {
    (void)prepare_planar(ses, po, 10);
    FAIL("not refused");
  } catch (const InputError& e) {
    const std::string m = e.what();
    INFO(m);
    CHECK(m.find("short.lcm") != std::string::npos);
    CHECK(m.find("needs at least 10") != std::string::npos);
    CHECK(m.find(std::to_string(sum.perturbed) + " usable perturbed trial") != std::string::npos);
  }
}

TEST_CASE("manipulandum: logs with different configurations are refused, naming both") {
  std::vector<CollectedSession> ses(2);
  ses[0].name = "a.lcm";
  ses[1].name = "b.lcm";
  ses[1].info.d_adm_nspm.x() = 20.0;
  try {
    (void)prepare_planar(ses, {}, 10);
    FAIL("not refused");
  } catch (const InputError& e) {
    const std::string m = e.what();
    INFO(m);
    CHECK(m.find("a.lcm and b.lcm") != std::string::npos);
    CHECK(m.find("d_adm_nspm[0]: 15 vs 20") != std::string::npos);
    CHECK(m.find("never pooled") != std::string::npos);
  }
}

TEST_CASE("manipulandum: mechanism columns against hand-computed values") {
  // One trial, 3 samples; rotation 90 degrees between workspace and shoulder.
  Dataset d;
  d.dt_s = 0.001;
  PlanarTrial p;
  p.ws_to_sh << 0, -1, 1, 0;
  p.m_bsp << 2, 0.5, 0.5, 1;
  p.dx = {{0, 0}, {0.001, 0.002}, {0.003, -0.001}};
  p.dxd = {{0, 0}, {0.1, -0.2}, {0.05, 0.3}};
  p.dxdd = {{1, 2}, {3, 4}, {5, 6}};
  p.u_pert_rate = {{10, 20}, {30, 40}, {50, 60}};
  p.xd_stage = {{0.0005, 0.2}, {0.1, 0.0}, {-0.3, 0.002}};
  p.du_ext_adm = p.du_ext_force = p.u_pert = p.dxdd;
  d.planar.push_back(p);
  for (int a = 0; a < 2; ++a) {
    Segment s;
    s.group = 0;
    s.axis = a;
    s.planar = 0;
    s.y.assign(3, 0.0);
    s.last = 3;
    d.segments.push_back(s);
  }
  const auto lib = planar_library();
  std::map<std::string, const Mechanism*> by;
  for (const auto& m : lib) by[m->id()] = m.get();
  // curl: row 1 +Δx2, row 2 -Δx1
  const auto cu = by.at("curl_stiffness")->columns(d, {});
  CHECK(cu[0][0][2] == Approx(-0.001));
  CHECK(cu[1][0][2] == Approx(-0.003));
  // delay: u̇_pert of the row
  const auto de = by.at("actuation_delay")->columns(d, {});
  CHECK(de[1][0][1] == Approx(40));
  // handle: Δẍ of the row; M_BSP: (M_BSP Δẍ) of the row
  CHECK(by.at("handle_mass")->columns(d, {})[0][0][2] == Approx(5));
  CHECK(by.at("wrong_segment_inertia")->columns(d, {})[1][0][1] == Approx(0.5 * 3 + 1 * 4));
  // friction: the trial's isolated series for the grid's v_s (prepared by
  // prepare_planar, isolated_stage_friction below), per row; v_s off the grid is refused.
  d.planar[0].friction_iso.assign(kStageFrictionVs.size(), std::vector<Eigen::Vector2d>(3, Eigen::Vector2d::Zero()));
  d.planar[0].friction_iso[2][1] = {0.25, -0.5};  // v_s = 1 mm/s
  d.planar[0].friction_iso[3][1] = {7.0, 8.0};    // v_s = 2 mm/s
  const double vs[] = {0.001};
  const auto fr = by.at("stage_friction")->columns(d, vs);
  CHECK(fr[0][0][1] == Approx(0.25));
  CHECK(fr[1][0][1] == Approx(-0.5));
  CHECK(fr[1][0][2] == 0.0);
  const double vs_off[] = {0.0015};
  CHECK_THROWS_AS(by.at("stage_friction")->columns(d, vs_off), std::invalid_argument);
  // reflex at 1 sample delay is rejected by the grid (20-60 ms); columns at 1 ms shift by one sample
  // (the column: the row of D_ref Δẋ(t − τ) + K_ref Δx(t − τ); without a reference D, K not applicable)
  CHECK_FALSE(by.at("short_latency_reflex")->not_applicable(d).empty());
  d.planar_ref_d << 10, 1, 2, 20;
  d.planar_ref_k << 300, -50, -50, 400;
  CHECK(by.at("short_latency_reflex")->not_applicable(d).empty());
  const double tau[] = {0.001};
  const auto re = by.at("short_latency_reflex")->columns(d, tau);
  CHECK(re[0][0][0] == 0.0);                                     // before the delay: Δ = 0
  CHECK(re[0][0][1] == 0.0);                                     // Δ(t − 1 ms) at sample 1 is sample 0: zero
  CHECK(re[0][0][2] == Approx(10 * 0.1 + 1 * -0.2 + 300 * 0.001 - 50 * 0.002));  // row 1 at sample 2
  CHECK(re[1][0][2] == Approx(2 * 0.1 + 20 * -0.2 - 50 * 0.001 + 400 * 0.002));  // row 2 at sample 2
}

TEST_CASE("manipulandum: stage friction column = tanh(v / v_s) through the force channel's isolation (SG rate, high-pass, integration from onset)") {
  // 2 s at 4 kHz, onset at 1 s, workspace rotated 90 degrees from the
  // shoulder frame. Workspace axis 1 reverses 75 ms after onset (+5 -> -5 cm/s),
  // axis 2 moves at a constant +10 cm/s: tanh(v / 1 mm/s) is +1 -> -1 on axis 1
  // and +1 throughout on axis 2.
  estimation::SessionInfo info;
  info.frame.rot_rad = std::numbers::pi / 2;
  const Eigen::Matrix2d R = info.frame.rotation();
  estimation::TrialData t;
  t.trial = 3;
  const std::size_t n = 8000, on = 4000, rev = on + 300;
  t.onset_index = static_cast<std::int64_t>(on);
  t.x_m.assign(n, Eigen::Vector2d::Zero());
  t.f_sensor_n = t.u_pert_n = t.x_ref_m = t.xdd_ref_m = t.x_m;
  for (std::size_t i = 0; i < n; ++i) t.xd_ref_m.push_back(R * Eigen::Vector2d(i < rev ? 0.05 : -0.05, 0.1));
  const estimation::PipelineSettings ps;  // SG 225 samples (56 ms), high-pass 1 Hz, T_est 0.15 s
  const auto iso = isolated_stage_friction(info, t, ps, R);
  REQUIRE(iso.size() == kStageFrictionVs.size());
  REQUIRE(iso[2].size() == 601);
  // Reference, written independently: the route of the force channel in
  // isolate_variational (SG first derivative, high-pass, integration from
  // onset) applied to the workspace series, then rotated. The column takes
  // the acceleration's route (SG jerk of the double integral); after the SG
  // window has passed the reversal (> 28 ms) both have the whole smoothed
  // step and agree. Not a plain step: the 1 Hz high-pass, zero-phase, moves
  // a 2 N step by ~0.2-0.6 within 150 ms, which the old column ignored.
  const double fs = info.sample_rate_hz, dt = 1.0 / fs;
  const dsp::SavgolFilter rate(estimation::sg_window_for(ps, fs), ps.sg_order, 1, dt);
  const auto sos = dsp::butter(ps.hp_order, ps.hp_cutoff_hz, fs, dsp::BandType::highpass);
  auto reference = [&](double vs, int axis) {
    std::vector<double> f(n), r(n), h(n), out(601);
    for (std::size_t i = 0; i < n; ++i) f[i] = std::tanh((R.transpose() * t.xd_ref_m[i])(axis) / vs);
    rate.apply(f, r);
    dsp::sosfiltfilt(sos, r, h);
    dsp::cumulative_trapezoid(std::span<const double>(h).subspan(on, 601), dt, out);
    return out;
  };
  for (std::size_t iv : {std::size_t{2}, kStageFrictionVs.size() - 1}) {
    const auto r1 = reference(kStageFrictionVs[iv], 0), r2 = reference(kStageFrictionVs[iv], 1);
    auto ws = [&](std::size_t k) { return Eigen::Vector2d(R.transpose() * iso[iv][k]); };
    INFO("v_s " << kStageFrictionVs[iv] << "; axis 1 at 0, 37, 75, 110, 150 ms: " << ws(0)(0) << " " << ws(150)(0) << " " << ws(300)(0) << " "
                << ws(440)(0) << " " << ws(600)(0) << "; reference " << r1[0] << " " << r1[150] << " " << r1[300] << " " << r1[440] << " " << r1[600]);
    CHECK(std::fabs(ws(0)(0)) < 1e-9);
    for (std::size_t k : {std::size_t{60}, std::size_t{150}, std::size_t{440}, std::size_t{520}, std::size_t{600}})
      CHECK(ws(k)(0) == Approx(r1[k]).margin(0.02 * std::fabs(r1[600])));
    // The reversal itself: a drop of 2 tanh(50 mm/s / v_s) across the SG
    // window, less what the high-pass takes over those 73 ms (-1.69 for -2).
    const double step = -2.0 * std::tanh(0.05 / kStageFrictionVs[iv]), drop = ws(440)(0) - ws(150)(0);
    CHECK(drop / step > 0.8);
    CHECK(drop / step < 0.9);
    // A constant sign is a constant force: removed like the unperturbed movement.
    for (std::size_t k = 0; k < 601; k += 50) {
      CHECK(std::fabs(ws(k)(1)) < 1e-6);
      CHECK(std::fabs(r2[k]) < 1e-6);
    }
  }
}

// The likelihood check end to end on a short session (50 movements, 3
// held-out folds). Release pass only: 340 s alone under ASan + UBSan on the
// 2-core machine (2026-12-04), against 190 s for the clean session that the
// sanitizer pass runs instead (scripts/test.sh).
TEST_CASE("manipulandum: likelihood check on a short session names a 2 ms delay") {
  Case c;
  c.effects = {sim::parse_hidden_effect("delay:0.002")};
  c.movements = 50;
  c.bootstrap = 10;
  c.heldout_folds = 3;
  const auto o = run_case(c);
  INFO("perturbed trials " << o.perturbed << "; named: " << (o.concl.named.empty() ? "none" : o.concl.named.front()));
  REQUIRE(o.lk.available);
  REQUIRE_FALSE(o.concl.named.empty());
  CHECK(o.concl.named.front() == "actuation_delay");
  const auto* f = o.named_fit("actuation_delay");
  REQUIRE(f);
  CHECK(f->heldout_done);
  CHECK(f->fold_gain_nats.size() == 3);
  CHECK(f->lr > 20.0);
}

// The sanitizer pass's named candidate: the path the clean session never
// takes (a candidate accepted, its held-out folds, a second round, the
// corrected D, K and their conclusion) on a session small enough for ASan +
// UBSan: 30 movements, a 4 ms delay and a two-mechanism library (the
// delay and the friction that competes with it, docs/diagnosis.md).
TEST_CASE("manipulandum: sanitizer-sized session: a named delay through its held-out folds and a second round") {
  Case c;
  c.effects = {sim::parse_hidden_effect("delay:0.004")};
  c.movements = 30;
  c.bootstrap = 5;
  c.heldout_folds = 3;
  c.mechanisms = {"actuation_delay", "stage_friction"};
  const auto o = run_case(c);
  INFO("perturbed trials " << o.perturbed << "; named: " << (o.concl.named.empty() ? "none" : o.concl.named.front()));
  REQUIRE(o.lk.available);
  REQUIRE(o.concl.named.size() == 1);
  CHECK(o.concl.named.front() == "actuation_delay");
  CHECK(o.lk.rounds.size() == 2);  // the friction profiled after the delay, not accepted
  const auto* f = o.named_fit("actuation_delay");
  REQUIRE(f);
  CHECK(f->fold_gain_nats.size() == 3);
  check_main_param(c.effects.front(), o);  // the delay within 20 %, a positive held-out gain
  CHECK(f->source == "force sensor");       // its correction takes the sensor's reading (sensor_delay.hpp)
  REQUIRE(o.concl.has_corrected);
  CHECK(o.concl.corrected.k.allFinite());
  CHECK(o.concl.corrected.d.allFinite());
}

TEST_CASE("manipulandum: a library restricted to an unknown mechanism is refused by name") {
  std::vector<CollectedSession> ses(1);
  PlanarOptions po;
  po.mechanisms = {"actuation_delay", "no_such_mechanism"};
  try {
    (void)run_planar(ses, po, EngineOptions{});
    FAIL("accepted");
  } catch (const std::invalid_argument& e) {
    CHECK(std::string(e.what()).find("'no_such_mechanism'") != std::string::npos);
  }
}

TEST_CASE("manipulandum: a clean session -> no significant misfit") {
  Case c;
  const auto o = run_case(c);
  INFO("accepted: " << (o.dg.accepted.empty() ? "none" : o.dg.accepted.front()) << "; named: " << (o.concl.named.empty() ? "none" : o.concl.named.front()));
  CHECK_FALSE(o.dg.misfit_found());
  REQUIRE(o.lk.available);
  CHECK(o.concl.named.empty());
  CHECK(o.concl.alternatives.empty());  // nothing named, nothing offered next to it
}

TEST_CASE("manipulandum: hidden actuation delay 2 ms is named, delay within 20 %, D and K after the extension") {
  Case c;
  c.effects = {sim::parse_hidden_effect("delay:0.002")};
  check_named(c, run_case(c));
}

TEST_CASE("manipulandum: hidden handle mass +0.3 kg is named, mass within 20 %, D and K after the extension") {
  Case c;
  c.effects = {sim::parse_hidden_effect("handle:0.3")};
  check_named(c, run_case(c));
}

// Friction at seed 1, with the column as the isolation leaves tanh(v / v_s)
// (isolated_stage_friction) and the pem refit given the unfiltered change of
// the friction force since onset: F 0.95 N, K within 1.2 %, D within 17 %
// (Frobenius). With the former column (F[tanh(v/v_s) − tanh((v − Δv)/v_s)])
// this case failed: F 0.76 N, D 21 % (it was tagged [.known-miss]).
TEST_CASE("manipulandum: hidden stage friction 1 N is named, F within 20 %, D and K after the extension") {
  Case c;
  c.effects = {sim::parse_hidden_effect("friction:1")};
  check_named(c, run_case(c));
}

// A pair: the greedy rounds fit the friction amplitude without the delay,
// which then held part of it (seeds 5000-5009: the delay 3-18 % short, D
// within 20 % in 1/10); the joint refit of the accepted amplitudes
// (likelihood_stage.cpp, refit_jointly) gives seed 1 F 0.94 N, delay 2.08 ms,
// D within 15 %, K within 3 % (Frobenius, apparent truth). Since 2026-12-06
// the delay is read from the force sensor and the friction refitted beside
// it (docs/diagnosis.md, "Actuation delay from the force sensor").
TEST_CASE("manipulandum: hidden delay 2 ms + friction 1 N are both named, each within 20 %, D and K after the joint refit") {
  Case c;
  c.effects = {sim::parse_hidden_effect("delay:0.002"), sim::parse_hidden_effect("friction:1")};
  const auto o = run_case(c);
  REQUIRE(o.lk.available);
  INFO("named: " << o.concl.named.size());
  for (const auto& e : c.effects) {
    const double v = check_main_param(e, o);
    const auto mp = main_param_of(e, o.draw, 4000.0);
    // The conclusion carries the joint value with its profile-likelihood interval.
    const auto j = conclusion_json(o.concl);
    REQUIRE(j["named_params"].contains(mp.id));
    const auto& jp = j["named_params"][mp.id][mp.param];
    CHECK(jp["value"].get<double>() == Approx(v));
    REQUIRE(jp.contains("ci95"));
    const double lo = jp["ci95"][0].get<double>(), hi = jp["ci95"][1].get<double>();
    INFO("interval [" << lo << ", " << hi << "]");
    CHECK(lo < v);
    CHECK(hi > v);
    CHECK(hi - lo < 0.5 * std::fabs(v));  // informative: narrower than ±25 %
  }
  // The delay read from the force sensor (its bootstrap interval above), the
  // friction's amplitude profiled beside it.
  const auto jc = conclusion_json(o.concl);
  CHECK(jc["named_params_source"]["actuation_delay"] == "force sensor");
  CHECK(jc["named_params_source"]["stage_friction"] == "likelihood");
  REQUIRE(o.concl.has_corrected);
  const auto& z = o.concl.corrected;
  INFO("K after " << show(z.k) << " truth " << show(o.k_app) << "; D after " << show(z.d) << " truth " << show(o.d_app));
  CHECK(frob(z.k, o.k_app) < 0.10);
  CHECK(frob(z.d, o.d_app) < 0.20);
  CHECK(frob(o.pem.d, o.d_app) > 0.20);  // the pair did move the default estimate
}

TEST_CASE("manipulandum: hidden short-latency reflex 0.5 K is named, delay within 20 %", "[.known-miss]") {
  Case c;
  c.effects = {sim::parse_hidden_effect("reflex:0.5")};
  check_named(c, run_case(c));
}

// The early feedback at the middle magnitude with realistic noise, seed 1
// (delay 90.8 ms): named first, but its delay 69.6 ms (−23 %) and gain 0.66
// trade against D, K in the window, and the corrected K11 is 24 % below the
// intrinsic (docs/diagnosis.md, "Early feedback"; the study gives the rates).
TEST_CASE("manipulandum: hidden early feedback 1.0 K is named, delay within 20 %, D and K after the extension", "[.known-miss]") {
  Case c;
  c.effects = {sim::parse_hidden_effect("feedback:1")};
  check_named(c, run_case(c));
}

// What the session does show of a reflex (docs/diagnosis.md, "The
// short-latency reflex in a 150 ms window"): with the corrections simulated
// from the model, the reflex itself is significant, its gain on a ridge with
// D, K (seed 1: LR 14.4, p_holm 0.005; named since the correction copies
// the fit's own D, K, "Pulse"; before, LR 13.2 with the gain at the edge of
// the profile, not named); nothing else is named in its place. When an
// inertia reduction is named instead, the reflex of the equivalent gain is
// offered next to it (checked here when it happens; the arithmetic below).
TEST_CASE("manipulandum: hidden short-latency reflex 0.5 K -> the reflex significant, nothing else named in its place") {
  Case c;
  c.effects = {sim::parse_hidden_effect("reflex:0.5")};
  const auto o = run_case(c);
  INFO("named: " << (o.concl.named.empty() ? "none" : o.concl.named.front()) << ", " << o.concl.alternatives.size() << " alternatives");
  for (const auto& n : o.concl.named) CHECK((n == "wrong_segment_inertia" || n == "handle_mass" || n == "short_latency_reflex"));
  REQUIRE(o.lk.available);
  REQUIRE_FALSE(o.lk.rounds.empty());
  const LikelihoodCandidate* reflex = nullptr;
  for (const auto& lc : o.lk.rounds.front().candidates)
    if (lc.id == "short_latency_reflex") reflex = &lc;
  REQUIRE(reflex);
  INFO("reflex LR " << reflex->lr << ", p_holm " << reflex->p_holm);
  CHECK(reflex->significant);
  for (const auto& a : o.concl.alternatives)
    if (a.id == "short_latency_reflex") {
      INFO("equivalent reflex gain " << a.gain << " (hidden 0.5)");
      CHECK(a.gain > 0.25);
      CHECK(a.gain < 1.0);
    }
}

// Within the window the delayed signals project on the undelayed ones:
// for Δx = sin ωt, Δx(t − τ) = cos ωτ Δx − (sin ωτ / ω) Δẋ and
// Δẋ(t − τ) = ω sin ωτ Δx + cos ωτ Δẋ exactly, except over the first τ, where
// the delayed signal is 0 (before onset); 40 periods make that a ~1 % effect.
TEST_CASE("manipulandum: delayed_projection of a sinusoid is the analytic shift") {
  Dataset d;
  d.dt_s = 0.00025;
  const double w = 2 * std::numbers::pi * 5.0, tau = 0.080;
  PlanarTrial p;
  for (std::size_t k = 0; k < 32000; ++k) {  // 8 s: 40 periods
    const double t = static_cast<double>(k) * d.dt_s;
    p.dx.emplace_back(std::sin(w * t), 0.5 * std::sin(w * t));
    p.dxd.emplace_back(w * std::cos(w * t), 0.5 * w * std::cos(w * t));
  }
  d.planar.push_back(p);
  const auto pr = delayed_projection(d, tau);
  CHECK(pr.a_x == Approx(std::cos(w * tau)).margin(0.02));
  CHECK(pr.b_x == Approx(-std::sin(w * tau) / w).margin(0.02 / w));
  CHECK(pr.a_v == Approx(w * std::sin(w * tau)).margin(0.02 * w));
  CHECK(pr.b_v == Approx(std::cos(w * tau)).margin(0.02));
  // τ = 0: the identity.
  const auto p0 = delayed_projection(d, 0.0);
  CHECK(p0.a_x == Approx(1.0));
  CHECK(p0.b_v == Approx(1.0));
  CHECK(std::fabs(p0.b_x) < 1e-9);
  CHECK(std::fabs(p0.a_v) < 1e-6);
}

// The delayed copies' model-based correction copies the fit's own D, K, so
// the person's D, K are the fixed point of "fit at the copy" (manipulandum.cpp,
// PlanarReflex). With the window's projection (a_x, b_x, a_v, b_v) the fit at
// a copy (D0, K0) returns K1 = K + g a_x (K − K0) + g a_v (D − D0) and
// D1 = D + g b_v (D − D0) + g b_x (K − K0); one step of next_reference from
// any (D0, K0) must land on D, K, for the reflex and the early feedback.
TEST_CASE("manipulandum: the delayed copies' next reference is the fixed point of a fit affine in the copied D, K") {
  const auto lib = planar_library(false, true);  // with the directional reflex
  Dataset d;
  d.dt_s = 0.00025;
  PlanarTrial p;
  for (std::size_t k = 0; k < 601; ++k) {  // a step response's shape over the 150 ms window
    const double t = static_cast<double>(k) * d.dt_s, e = std::exp(-t / 0.05);
    p.dx.emplace_back(0.01 * (1 - e * (1 + t / 0.05)), -0.004 * (1 - e * (1 + t / 0.05)));
    p.dxd.emplace_back(0.01 * t / (0.05 * 0.05) * e, -0.004 * t / (0.05 * 0.05) * e);
  }
  d.planar.push_back(p);
  Matrix2d d_true, k_true, d0, k0;
  d_true << 12.0, -3.0, -3.0, 8.0;
  k_true << 150.0, -60.0, -60.0, 340.0;
  d0 << 20.0, -7.0, -7.0, 15.0;  // the baseline's apparent D, K: the starting copy
  k0 << 420.0, -150.0, -150.0, 900.0;
  const double share = 0.4, g = share / (1 - share);
  const std::vector<double> gains{share};
  for (const auto& [id, tau] : {std::pair<std::string, double>{"short_latency_reflex", 0.031}, {"early_feedback", 0.090}}) {
    INFO(id);
    const Mechanism* m = find_mechanism(lib, id);
    REQUIRE(m);
    const auto pr = delayed_projection(d, tau);
    const std::vector<double> setting{tau};
    Matrix2d k1 = k_true + g * pr.a_x * (k_true - k0) + g * pr.a_v * (d_true - d0);
    Matrix2d d1 = d_true + g * pr.b_v * (d_true - d0) + g * pr.b_x * (k_true - k0);
    m->next_reference(d, setting, gains, d0, k0, d1, k1);
    CHECK((k1 - k_true).norm() < 1e-9 * k_true.norm());
    CHECK((d1 - d_true).norm() < 1e-9 * d_true.norm());
  }
  // The directional reflex acts through P = f w wᵀ, f the stretch share of
  // the copy's energy along w at (D0, K0): with a second trial pushed the
  // other way at 0.6 × the amplitude, f = 1/(1 + 0.36) on the first trial's
  // side. The projection is the same for both trials (one shape, scaled).
  {
    Dataset d2 = d;
    PlanarTrial q = p;
    for (auto& v : q.dx) v *= -0.6;
    for (auto& v : q.dxd) v *= -0.6;
    d2.planar.push_back(q);
    const double tau = 0.031, psi = -0.5;
    const Eigen::Vector2d w(std::cos(psi), std::sin(psi));
    const auto lag = static_cast<std::size_t>(std::lround(tau / d.dt_s));
    REQUIRE(w.dot(d0 * p.dxd[300 - lag] + k0 * p.dx[300 - lag]) > 0);  // the first trial stretches along w
    const Matrix2d pw = (1.0 / 1.36) * w * w.transpose();
    const auto pr = delayed_projection(d2, tau);
    Matrix2d k1 = k_true + g * pw * (pr.a_x * (k_true - k0) + pr.a_v * (d_true - d0));
    Matrix2d d1 = d_true + g * pw * (pr.b_x * (k_true - k0) + pr.b_v * (d_true - d0));
    const Mechanism* m = find_mechanism(lib, "directional_reflex");
    REQUIRE(m);
    m->next_reference(d2, std::vector<double>{tau, psi}, gains, d0, k0, d1, k1);
    CHECK((k1 - k_true).norm() < 1e-9 * k_true.norm());
    CHECK((d1 - d_true).norm() < 1e-9 * d_true.norm());
  }
  // For a short delay the projection is the first-order shift Δx(t − τ) ≈ Δx − τ Δẋ.
  const auto ps = delayed_projection(d, 0.002);
  CHECK(ps.a_x == Approx(1.0).margin(0.02));
  CHECK(ps.b_x == Approx(-0.002).margin(0.0002));
  // Other mechanisms keep the fit as the next reference.
  const Mechanism* handle = find_mechanism(lib, "handle_mass");
  REQUIRE(handle);
  Matrix2d dd = d_true, kk = k_true;
  handle->next_reference(d, {}, gains, d0, k0, dd, kk);
  CHECK(dd == d_true);
  CHECK(kk == k_true);
}

// With a short pulse the same reflex is named (docs/diagnosis.md, "Pulse"):
// 50 ms at 20 N excites the response where the reflex's delay shows, before
// its first τ and after. The reflex's parameters and the intrinsic D, K it
// separates from the apparent ones: the delay within 20 %, the gain within
// 30 %, K and D within 15 % and 20 % of the intrinsic truth where the plain
// `pem` holds the reflex (K ≈ (1 + g) K_i). K within 15 %, not 10 %: the
// short pulse carries less of the stiffness (the clean sessions' K at 50 ms:
// within 10 % in 3/5, "Pulse").
namespace {
void check_reflex_05_short_pulse(std::uint64_t hidden_seed) {
  Case c;
  c.hidden_seed = hidden_seed;
  c.effects = {sim::parse_hidden_effect("reflex:0.5")};
  c.pulse_s = 0.05;
  c.pulse_n = 20.0;
  const auto o = run_case(c);
  check_delayed_copy(c, o, "reflex_gain", 0.30, 0.15, 0.20);
  CHECK(frob(o.pem.k, o.k_intr) > 0.30);
  // Each held-out fold searched the delay on its training trials
  // (docs/diagnosis.md, "Held-out shapes"): ten delays, each near the hidden one.
  const auto* f = o.named_fit("short_latency_reflex");
  REQUIRE(f);
  CHECK(f->heldout_done);
  REQUIRE(f->fold_settings.size() == 10);
  for (const auto& s : f->fold_settings) {
    REQUIRE(s.size() == 1);
    INFO("fold delay " << s[0] << ", hidden " << o.draw.reflex_delay_s);
    CHECK(std::fabs(rel(s[0], o.draw.reflex_delay_s)) < 0.20);
  }
  // The delay's 95 % profile-likelihood interval (its profile over the
  // delays searched, "The delay's interval"): it holds the hidden delay,
  // reaches past the named one on the side the search profiled beyond it,
  // and is narrower than the grid's 5 ms steps either way (10 ms; seed 2:
  // 8.1 ms, the study's median at 0.5: 5.6 ms). An end at the search's
  // lowest delay (22 ms) is open there, not invented below it.
  const auto* delay = param_named(*f, "delay");
  REQUIRE(delay);
  INFO("delay " << delay->est.value << " [" << delay->est.lo << (delay->lo_open ? " open" : "") << ", " << delay->est.hi
                << (delay->hi_open ? " open" : "") << "], hidden " << o.draw.reflex_delay_s);
  CHECK(delay->est.lo <= o.draw.reflex_delay_s);
  CHECK(delay->est.hi >= o.draw.reflex_delay_s);
  CHECK(delay->est.hi > delay->est.value);
  CHECK_FALSE(delay->hi_open);
  CHECK(delay->est.hi - delay->est.lo < 0.010);
  if (delay->lo_open) CHECK(delay->est.lo == Approx(0.022).margin(1e-9));
  // The report prints it: text "delay 0.0… [lo, hi] s", JSON ci95 (and ci95_open where open).
  const auto j = param_json(*delay);
  CHECK(j["ci95"][1] == delay->est.hi);
  CHECK(j.contains("ci95_open") == (delay->lo_open || delay->hi_open));
}
}  // namespace

// Hidden seed 2 (delay 32.71 ms): the first seed after 1 whose delay lies
// more than 1 ms inside the generator's 25-35 ms, chosen so by that rule
// (docs/diagnosis.md, "The profile from 22 ms"); named at 31.82 ms
// [27.51, 35.63] both with the profile from 25 ms and from 22 ms.
TEST_CASE("manipulandum: hidden short-latency reflex 0.5 with a 50 ms, 20 N pulse is named - the intrinsic D, K recovered") {
  check_reflex_05_short_pulse(2);
}

// Hidden seed 1 (delay 25.38 ms, on the generator's lower bound), the CI
// case until 2026-12-08: its profile falls towards short delays, so it is
// named at the search's lowest delay, 22 ms [<22, 27.25] (truth inside),
// and K is 17.2 % off the intrinsic truth (15 % allowed). From 25 ms it was
// named at 25.0 ms, within 15 %, the grid's edge on the generator's bound.
TEST_CASE("manipulandum: hidden short-latency reflex 0.5 on the lower bound of the generated delays, 50 ms pulse - K within 15 %", "[.known-miss]") {
  check_reflex_05_short_pulse(1);
}

// The model-based correction's passes to its fixed point (docs/diagnosis.md,
// "Passes to the fixed point"): a strong reflex (gain 1.0, the apparent K
// about twice the intrinsic one) puts the reference D, K it is simulated at
// far from where the first fit lands. Noise-free, so the check is of the
// fixed point, not of the session's power. Hidden seed 5000 (delay 32.76 ms,
// between grid points), the library restricted to the reflex, 40 movements
// and 3 held-out folds for time. Measured (2026-12-07): two fixed passes,
// as before, named 30.77 ms (−2.0 ms) with K 4.4 % and D 8.9 % off the
// intrinsic truth; passes until the reference settles 32.41 ms (−0.35 ms),
// K 0.6 %, D 0.7 % (a settle 10 times tighter gives the same delay: the rest
// is not the passes').
TEST_CASE("manipulandum: hidden strong reflex 1.0, noise-free - passes to the fixed point recover the delay and the intrinsic D, K") {
  Case c;
  c.effects = {sim::parse_hidden_effect("reflex:1")};
  c.hidden_seed = 5000;
  c.movements = 40;
  c.noise = sim::parse_noise_level("none");
  c.pulse_s = 0.05;
  c.pulse_n = 20.0;
  c.heldout_folds = 3;
  c.mechanisms = {"short_latency_reflex"};
  const auto o = run_case(c);
  REQUIRE_FALSE(o.concl.named.empty());
  CHECK(o.concl.named.front() == "short_latency_reflex");
  const auto* f = o.named_fit("short_latency_reflex");
  REQUIRE(f);
  const auto* delay = param_named(*f, "delay");
  REQUIRE(delay);
  REQUIRE(o.concl.has_corrected);
  INFO("delay " << delay->est.value << ", hidden " << o.draw.reflex_delay_s << "; K after " << show(o.concl.corrected.k) << ", D after "
                << show(o.concl.corrected.d) << ", intrinsic K " << show(o.k_intr) << ", D " << show(o.d_intr));
  CHECK(std::fabs(delay->est.value - o.draw.reflex_delay_s) < 0.0006);
  CHECK(frob(o.concl.corrected.k, o.k_intr) < 0.02);
  CHECK(frob(o.concl.corrected.d, o.d_intr) < 0.02);
}

// Feedback earlier than the model's T_est (docs/diagnosis.md, "Early
// feedback"): a delayed copy of the person's D, K at 60-100 ms. Noise-free,
// so the test checks the mechanism and its fixed point rather than the
// session's power (with realistic noise it is named in the study's share of
// sessions): named first, its delay within 20 %, and the corrected D, K on
// the intrinsic truth where the plain `pem` holds the feedback. Measured on
// hidden seed 1 (delay 90.8 ms, 2026-12-04): delay 90.0 ms, gain 0.430
// against the hidden 0.5 (−14 %; 40 % allowed: a longer delay with a larger
// gain leaves nearly the same response in the window, and earlier versions
// gave 0.67), K and D within 0.6 % of the intrinsic truth, the apparent K
// 11 % above it (noise-free, the plain `pem` K stays near the intrinsic one:
// without noise its fit of the whole response does not take the feedback
// into K, as it does with realistic noise).
TEST_CASE("manipulandum: hidden early feedback 0.5 at 60-100 ms, noise-free, is named - the intrinsic D, K recovered") {
  Case c;
  c.effects = {sim::parse_hidden_effect("feedback:0.5")};
  c.noise = sim::parse_noise_level("none");
  // Noise-free `pem` fits converge slowly (~34 Fisher-scoring iterations a
  // fit against ~2.5 with realistic noise, some stopping at the 80 allowed),
  // so this is the suite's longest case: 3 held-out folds, and two
  // repetitions per angle (16 perturbed trials) instead of three. Noise-free,
  // the repetitions of an angle carry the same response: 16 and 24 trials
  // give the figures above to three digits, in 181 s and 260 s alone on the
  // 2-core machine (2026-12-04). One repetition (8 trials) is below the
  // 10-fold equation-error search's minimum of 10. The diagnosis tests'
  // timeout is 1200 s (tests/CMakeLists.txt).
  c.heldout_folds = 3;
  c.reps = 2;
  const auto o = run_case(c);
  check_delayed_copy(c, o, "feedback_gain", 0.40, 0.05, 0.05);
  // The feedback is in the window: the apparent K holds it (+20 % on K11).
  CHECK(frob(o.k_app, o.k_intr) > 0.05);
}

// A direction-dependent reflex (docs/diagnosis.md, "Direction-dependent
// reflex"): one muscle group's short-latency reflex, along w and only when a
// deviation along w stretches it, at the middle magnitude under the paper's
// pulse, realistic noise, hidden seed 1: named first, its delay within 20 %
// with a positive held-out gain, its direction within 45° (the likelihood
// check's grid step) of the hidden one, and the corrected D, K against the
// intrinsic truth (the plain `pem` holds the reflex's symmetric half).
TEST_CASE("manipulandum: hidden directional reflex 1.0 is named - direction, delay, the intrinsic D, K") {
  Case c;
  c.effects = {sim::parse_hidden_effect("reflex_dir:1")};
  c.directional = true;
  // 5 held-out folds, as the study: each fold searches the delay and the
  // direction on its training trials ("Held-out shapes"); with the engine's
  // 10 the case took 139 s in CI (66 s before the per-fold search).
  c.heldout_folds = 5;
  const auto o = run_case(c);
  check_delayed_copy(c, o, "reflex_gain", 0.30, 0.10, 0.20);
  const auto* f = o.named_fit("directional_reflex");
  REQUIRE(f);
  CHECK(f->fold_settings.size() == 5);
  const auto* dir = param_named(*f, "direction");
  const double psi = dir ? dir->est.value : NAN;
  const double err = std::remainder(psi - o.draw.reflex_direction_rad, 2 * std::numbers::pi);
  INFO("direction " << psi << " rad, hidden " << o.draw.reflex_direction_rad << " rad");
  CHECK(std::fabs(err) < std::numbers::pi / 4);
}

// The conclusion's alternative to a named inertia reduction: the reflex gain
// g whose second-order inertia g (τ² K_i/2 − τ D_i) equals the named ΔM, with
// the intrinsic D_i, K_i recovered from the corrected (reflex-holding) D, K:
// K = (1 + g) K_i, D = (1 + g) D_i − g τ K_i (docs/diagnosis.md). Checked by
// putting the reported g back into these definitions.
TEST_CASE("manipulandum: the reflex offered for a named inertia reduction has the gain of the same inertia change") {
  PlanarPrepared prep;
  PlanarTrial t;
  t.m_bsp << 1.8, 0.3, 0.3, 1.2;
  prep.data.planar = {t, t};
  LikelihoodStage st;
  st.available = true;
  st.fit.available = true;
  st.fit.d << 14.0, -4.0, -4.0, 9.0;
  st.fit.k << 200.0, -80.0, -80.0, 420.0;
  LikelihoodCandidate lc;
  lc.id = "wrong_segment_inertia";
  lc.params.push_back({"mbsp_error", "1", {-0.05, -0.05, -0.05}, -0.5, 0.5, true});
  st.accepted = {lc.id};
  st.accepted_fits = {lc};
  const auto concl = conclude(Diagnosis{}, st, prep);
  REQUIRE(concl.alternatives.size() == 1);
  const auto& a = concl.alternatives.front();
  CHECK(a.named == "wrong_segment_inertia");
  CHECK(a.id == "short_latency_reflex");
  const double g = a.gain, tau = a.delay_s;
  REQUIRE(g > 0);
  const Matrix2d ki = st.fit.k / (1 + g), di = (st.fit.d + g * tau * ki) / (1 + g);
  const double dm = g * (tau * tau / 2 * ki.trace() - tau * di.trace());
  CHECK(dm == Approx(-0.05 * t.m_bsp.trace()).epsilon(1e-6));
  // No inertia reduction, no alternative.
  st.accepted_fits.front().params.front().est = {0.05, 0.05, 0.05};
  CHECK(conclude(Diagnosis{}, st, prep).alternatives.empty());
  // The paper's 150 ms pulse cannot show a reflex (docs/diagnosis.md,
  // "Pulse"): the conclusion says so and which pulse would; a 50 ms pulse
  // or a named reflex needs no note.
  prep.info.perturbation.duration_s = 0.15;
  const auto c150 = conclude(Diagnosis{}, st, prep);
  CHECK(c150.protocol_note.find("150 ms pulse") != std::string::npos);
  CHECK(c150.protocol_note.find("50 ms, 20 N") != std::string::npos);
  CHECK(conclusion_text(c150, Diagnosis{}).find("Not visible: under this session's 150 ms pulse") != std::string::npos);
  CHECK(conclusion_json(c150)["protocol_note"] == c150.protocol_note);
  prep.info.perturbation.duration_s = 0.05;
  CHECK(conclude(Diagnosis{}, st, prep).protocol_note.empty());
  prep.info.perturbation.duration_s = 0.15;
  st.accepted = {"short_latency_reflex"};
  st.accepted_fits.front().id = "short_latency_reflex";
  CHECK(conclude(Diagnosis{}, st, prep).protocol_note.empty());
}

TEST_CASE("manipulandum: hidden curl 40 N/m is named, c within 20 %", "[.known-miss]") {
  Case c;
  c.effects = {sim::parse_hidden_effect("curl:40")};
  check_named(c, run_case(c));
}

TEST_CASE("manipulandum: model-based corrections drive the baseline model along the extended plant's response") {
  // The correction e of a linear mechanism (simulate_extension: RK4 on the
  // extended plant) must make the baseline variational model reproduce the
  // extended plant: given u − e, the baseline's exact zero-order-hold
  // response (estimation::discretise_variational, matrix exponential, an
  // independent path) must feel the mechanism's force e along itself:
  //   handle ΔM Δẍ, M_BSP error s M_BSP Δẍ, curl [0 c; −c 0] Δx,
  //   reflex g (D Δẋ + K Δx)(t − τ) at the person's own D, K, g = 0.4/(1 − 0.4),
  //   directional reflex g w max(0, wᵀ (D Δẋ + K Δx)(t − τ)), w at −0.4 rad
  //   (the response's side: it acts), then at π − 0.4 rad (it does not),
  // averaged over each hold (Δẍ: Δv over the hold / h; the others: the
  // trapezoid, whose O(h²) error bounds the tolerance).
  Dataset d = one_pulse_trial();
  const PlanarTrial& p = d.planar.front();
  const std::size_t n = p.u_pert.size();
  Matrix2d dm, km;
  dm << 12.0, -3.0, -3.0, 8.0;
  km << 150.0, -60.0, -60.0, 340.0;
  estimation::OeWindow w;
  w.fs_hz = 1.0 / d.dt_s;
  w.m_total_kg = p.m_adm + p.m_handle + p.m_bsp;
  w.m_bsp_kg = p.m_bsp;
  w.d_adm_nspm = p.d_adm;
  const auto zoh = estimation::discretise_variational(w, dm, km);
  const auto lib = planar_library(false, true);  // with the directional reflex
  struct Probe {
    std::string id;
    double gain;
    std::function<Eigen::Vector2d(const std::vector<Eigen::Vector4d>&, std::size_t)> force;  // hold mean over [k, k+1]
    std::vector<double> setting{0.030};
  };
  const Matrix2d curl = (Matrix2d() << 0.0, 40.0, -40.0, 0.0).finished();
  const std::size_t lag = 120;  // 30 ms
  auto at = [](const std::vector<Eigen::Vector4d>& z, std::size_t k, const Matrix2d& dd, const Matrix2d& kk) -> Eigen::Vector2d {
    return dd * z[k].tail<2>() + kk * z[k].head<2>();
  };
  const std::vector<Probe> probes = {
      {"handle_mass", 0.3, [&](const auto& z, std::size_t k) { return Eigen::Vector2d(0.3 * (z[k + 1].template tail<2>() - z[k].template tail<2>()) / d.dt_s); }},
      {"wrong_segment_inertia", -0.2,
       [&](const auto& z, std::size_t k) { return Eigen::Vector2d(-0.2 * p.m_bsp * (z[k + 1].template tail<2>() - z[k].template tail<2>()) / d.dt_s); }},
      {"curl_stiffness", 40.0, [&](const auto& z, std::size_t k) { return Eigen::Vector2d(0.5 * curl * (z[k].template head<2>() + z[k + 1].template head<2>())); }},
      {"short_latency_reflex", 0.4,
       [&](const auto& z, std::size_t k) {
         if (k < lag) return Eigen::Vector2d(Eigen::Vector2d::Zero());
         return Eigen::Vector2d(0.4 / 0.6 * 0.5 * (at(z, k - lag, dm, km) + at(z, k + 1 - lag, dm, km)));
       }},
  };
  std::vector<Probe> all = probes;
  for (const double psi : {-0.4, std::numbers::pi - 0.4}) {
    const Eigen::Vector2d u(std::cos(psi), std::sin(psi));
    auto one_sided = [&, u](const auto& z, std::size_t k) {
      if (k < lag) return Eigen::Vector2d(Eigen::Vector2d::Zero());
      auto f = [&](std::size_t j) { return Eigen::Vector2d(u * std::max(0.0, u.dot(at(z, j - lag, dm, km)))); };
      return Eigen::Vector2d(0.4 / 0.6 * 0.5 * (f(k) + f(k + 1)));
    };
    all.push_back({"directional_reflex", 0.4, one_sided, {0.030, psi}});
  }
  for (const auto& pr : all) {
    const Mechanism* m = find_mechanism(lib, pr.id);
    REQUIRE(m);
    const std::vector<double> g{pr.gain};
    const auto e = m->model_correction(d, pr.setting, g, dm, km);
    REQUIRE(e.size() == 1);
    REQUIRE(e[0].size() == n);
    std::vector<Eigen::Vector4d> z(n, Eigen::Vector4d::Zero());
    for (std::size_t k = 0; k + 1 < n; ++k) z[k + 1] = zoh.phi * z[k] + zoh.gam * (p.u_pert[k] - e[0][k]);
    double worst = 0.0, peak = 0.0;
    for (std::size_t k = 0; k + 1 < n; ++k) {
      const Eigen::Vector2d f = pr.force(z, k);
      worst = std::max(worst, (e[0][k] - f).norm());
      peak = std::max(peak, f.norm());
    }
    INFO(pr.id << " at " << pr.setting.back() << ": largest difference " << worst << " N, peak force " << peak << " N");
    if (pr.setting.size() > 1 && pr.setting[1] > 1.0) {  // the directional reflex on the shortened side
      CHECK(peak == 0.0);
      CHECK(worst < 1e-9);  // rounding only (measured 2e-15 N)
      continue;
    }
    CHECK(peak > 0.05);
    CHECK(worst < 1e-5 * peak);  // measured 5e-9 (inertias) to 1e-6 (curl) of the peak
  }
}

// ---------------------------------------------------------------- study (not in CI)
// build/tests/test_diagnosis "[.mstudy]" -s ; MANIP_MSTUDY_SEEDS (default 20),
// MANIP_MSTUDY_CELLS (comma list of "none", "delay:0.002", ... default all),
// MANIP_MSTUDY_FIRST (first hidden seed, 5000), MANIP_MSTUDY_REPS (perturbed
// repetitions per angle, 3), MANIP_MSTUDY_PULSE_S / MANIP_MSTUDY_PULSE_N (the
// perturbation pulse's duration and amplitude; default the paper's 0.15 s,
// 15 N), MANIP_MSTUDY_NOISE (none ... realistic, the default), MANIP_MSTUDY_DIRECTIONAL=1 (the
// library with the direction-dependent reflex), MANIP_MSTUDY_MECHANISMS (comma
// list of ids: the library restricted to them, diagnose_model --mechanisms),
// MANIP_MSTUDY_VERBOSE=1 (per session on stderr).
TEST_CASE("manipulandum: detection study", "[.mstudy]") {
  const char* se = std::getenv("MANIP_MSTUDY_SEEDS");
  const int seeds = se ? std::atoi(se) : 20;
  const char* fs = std::getenv("MANIP_MSTUDY_FIRST");  // first hidden seed (default 5000)
  const std::uint64_t first_seed = fs ? std::strtoull(fs, nullptr, 10) : 5000;
  std::vector<std::string> cells = {"none",         "delay:0.001",  "delay:0.002", "delay:0.004", "friction:0.5",
                                    "friction:1",   "friction:2",   "handle:0.15", "handle:0.3",  "handle:0.6",
                                    "reflex:0.25",  "reflex:0.5",   "reflex:1",    "feedback:0.5", "feedback:1", "feedback:1.5", "reflex_dir:0.5", "reflex_dir:1", "reflex_dir:1.5", "curl:20",     "curl:40",
                                    "curl:80",      "sensor_lag:0.0015", "sensor_lag:0.003", "sensor_lag:0.006",
                                    "delay:0.002+friction:1", "curl:40+handle:0.3"};
  const char* rp = std::getenv("MANIP_MSTUDY_REPS");  // perturbed repetitions per angle (default 3: 24 perturbed trials)
  const int reps = rp ? std::max(1, std::atoi(rp)) : 3;
  if (const char* cs = std::getenv("MANIP_MSTUDY_CELLS")) {
    cells.clear();
    std::stringstream ss(cs);
    std::string t;
    while (std::getline(ss, t, ',')) cells.push_back(t);
  }
  std::printf("| hidden | sessions | named first | all named | main param within 20 %% | held-out gain > 0 | K within 10 %% | D within 20 %% | K11, K22 within 10 %% | D11, D22 within 20 %% | K within 10 %%, no extension | D within 20 %%, no extension | false names | median main err | above detection limit | median limit / magnitude | reflex as the alternative, gain within 30 %% | main param in its 95 %% interval |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const auto& cell : cells) {
    std::vector<sim::HiddenEffect> eff;
    if (cell != "none") {
      std::stringstream ss(cell);
      std::string t;
      while (std::getline(ss, t, '+')) eff.push_back(sim::parse_hidden_effect(t));
    }
    int first = 0, all = 0, mainok = 0, gain = 0, kok = 0, dok = 0, falsen = 0, kf = 0, df = 0, k0 = 0, d0 = 0;
    std::vector<double> errs, ratio;
    int above = 0, alt = 0, covered = 0, with_interval = 0;
    for (int s = 0; s < seeds; ++s) {
      Case c;
      c.effects = eff;
      c.hidden_seed = first_seed + static_cast<std::uint64_t>(s);
      c.reps = reps;
      c.movements = (100 * reps + 2) / 3;  // the default density: 24 perturbed trials in 100 movements
      if (const char* ps = std::getenv("MANIP_MSTUDY_PULSE_S")) c.pulse_s = std::atof(ps);
      if (const char* pn = std::getenv("MANIP_MSTUDY_PULSE_N")) c.pulse_n = std::atof(pn);
      if (const char* nz = std::getenv("MANIP_MSTUDY_NOISE")) c.noise = sim::parse_noise_level(nz);
      // The direction-dependent reflex is in the library on request only.
      c.directional = std::getenv("MANIP_MSTUDY_DIRECTIONAL") != nullptr;
      if (const char* ms = std::getenv("MANIP_MSTUDY_MECHANISMS")) {
        std::stringstream ss(ms);
        for (std::string t; std::getline(ss, t, ',');) c.mechanisms.push_back(t);
      }
      // The held-out check decides only for second and later names: pairs
      // get diagnose_model's 10 folds; single mechanisms 5 (half the pem
      // fits; there only the "held-out gain > 0" column depends on it).
      c.heldout_folds = eff.size() > 1 ? -1 : 5;
      const auto o = run_case(c);
      const bool delayed = !eff.empty() && separates_feedback(eff.front());
      Matrix2d kt = delayed ? o.k_intr : o.k_app, dt = delayed ? o.d_intr : o.d_app;
      const Matrix2d k = o.concl.has_corrected ? o.concl.corrected.k : o.pem.k;
      const Matrix2d dd = o.concl.has_corrected ? o.concl.corrected.d : o.pem.d;
      if (worst_diag(k, kt) < 0.10) ++kok;
      if (worst_diag(dd, dt) < 0.20) ++dok;
      if (frob(k, kt) < 0.10) ++kf;
      if (frob(dd, dt) < 0.20) ++df;
      if (frob(o.pem.k, kt) < 0.10) ++k0;
      if (frob(o.pem.d, dt) < 0.20) ++d0;
      const auto& named = o.concl.named;
      if (std::getenv("MANIP_MSTUDY_VERBOSE")) {
        std::fprintf(stderr, "%s seed %llu: named", cell.c_str(), static_cast<unsigned long long>(c.hidden_seed));
        for (const auto& n : named) std::fprintf(stderr, " %s", n.c_str());
        std::fprintf(stderr, " (equation error:");
        for (const auto& n : o.dg.accepted) std::fprintf(stderr, " %s", n.c_str());
        std::fprintf(stderr, ")");
        for (const auto& r : o.lk.rounds)
          for (const auto& lc : r.candidates)
            if (lc.significant) std::fprintf(stderr, "; %s LR %.1f p_holm %.2g relevance %.2f", lc.id.c_str(), lc.lr, lc.p_holm, lc.relevance);
        for (const auto& lc : o.lk.accepted_fits)
          if (lc.heldout_done) std::fprintf(stderr, "; held-out %s %+.3f +- %.3f", lc.id.c_str(), lc.heldout.mean, lc.heldout.se);
        for (const auto& a : o.concl.alternatives) std::fprintf(stderr, "; or %s gain %.3f", a.id.c_str(), a.gain);
        for (const auto& n : named)
          if (const auto* f = o.named_fit(n))
            for (const auto& p : f->params) std::fprintf(stderr, "; %s.%s %.4g [%.4g, %.4g]", n.c_str(), p.name.c_str(), p.est.value, p.est.lo, p.est.hi);
        // Signed relative errors of the reported D, K (diagonals) and their
        // Frobenius errors: which way the corrected estimate misses.
        for (const auto& e : eff)
          if (const auto mp = main_param_of(e, o.draw, 4000.0); const auto* f = o.named_fit(mp.id))
            if (const auto* p = param_named(*f, mp.param); p && p->est.hi > p->est.lo)
              std::fprintf(stderr, "; truth %s %.4g %s its interval", mp.param.c_str(), mp.truth,
                           mp.truth >= p->est.lo && mp.truth <= p->est.hi ? "inside" : "outside");
        if (!eff.empty() && eff.front().mechanism == sim::HiddenMechanism::reflex_dir)
          std::fprintf(stderr, "; truth direction %.4g delay %.4g", o.draw.reflex_direction_rad, o.draw.reflex_delay_s);
        std::fprintf(stderr, "; err D11 %+.3f D22 %+.3f K11 %+.3f K22 %+.3f |D| %.3f |K| %.3f", rel(dd(0, 0), dt(0, 0)),
                     rel(dd(1, 1), dt(1, 1)), rel(k(0, 0), kt(0, 0)), rel(k(1, 1), kt(1, 1)), frob(dd, dt), frob(k, kt));
        std::fprintf(stderr, "\n");
      }
      if (eff.empty()) {
        if (!named.empty()) ++falsen;
        continue;
      }
      for (const auto& a : o.concl.alternatives)
        if (eff.front().mechanism == sim::HiddenMechanism::reflex && a.id == "short_latency_reflex" &&
            std::fabs(rel(a.gain, eff.front().magnitude)) < 0.30) {
          ++alt;
          break;
        }
      if (const auto lim = limit_of(o, eff.front()); std::isfinite(lim.limit)) {
        ratio.push_back(lim.limit / std::fabs(lim.truth));
        if (std::fabs(lim.truth) > lim.limit) ++above;
      }
      std::vector<std::string> ids;
      for (const auto& e : eff) ids.push_back(main_param_of(e, o.draw, 4000.0).id);
      if (!named.empty() && std::find(ids.begin(), ids.end(), named.front()) != ids.end()) ++first;
      bool every = true;
      for (const auto& id : ids) every = every && std::find(named.begin(), named.end(), id) != named.end();
      if (every) ++all;
      for (const auto& a : named)
        if (std::find(ids.begin(), ids.end(), a) == ids.end()) ++falsen;
      const auto mp = main_param_of(eff.front(), o.draw, 4000.0);
      if (const auto* f = o.named_fit(mp.id)) {
        if (const auto* p = param_named(*f, mp.param)) {
          const double er = std::fabs(rel(p->est.value, mp.truth));
          errs.push_back(er);
          if (er < 0.2) ++mainok;
          if (p->est.hi > p->est.lo) {
            ++with_interval;
            if (mp.truth >= p->est.lo && mp.truth <= p->est.hi) ++covered;
          }
        }
        if (f->heldout_done && f->heldout.mean > 0) ++gain;
      }
    }
    std::sort(errs.begin(), errs.end());
    const double med = errs.empty() ? NAN : errs[errs.size() / 2];
    std::sort(ratio.begin(), ratio.end());
    const double medr = ratio.empty() ? NAN : ratio[ratio.size() / 2];
    if (eff.empty())
      std::printf("| none | %d | no false alarm %d/%d | | | | %d/%d | %d/%d | %d/%d | %d/%d | %d/%d | %d/%d | %d | | | | | |\n", seeds, seeds - falsen, seeds, kf, seeds,
                  df, seeds, kok, seeds, dok, seeds, k0, seeds, d0, seeds, falsen);
    else
      std::printf("| %s | %d | %d/%d | %d/%d | %d/%d | %d/%d | %d/%d | %d/%d | %d/%d | %d/%d | %d/%d | %d/%d | %d | %.3f | %d/%d | %.2f | %s | %d/%d |\n", cell.c_str(), seeds, first, seeds, all,
                  seeds, mainok, seeds, gain, seeds, kf, seeds, df, seeds, kok, seeds, dok, seeds, k0, seeds, d0, seeds, falsen, med, above, seeds, medr,
                  eff.front().mechanism == sim::HiddenMechanism::reflex ? (std::to_string(alt) + "/" + std::to_string(seeds)).c_str() : "", covered,
                  with_interval);
    std::fflush(stdout);
  }
}

// A diagnosis moved to the reference by the stages' tracking, nothing else
// named: the corrected impedance is the default method on the reference, and
// the tracked estimate (the tracking as a known force on the encoder) is
// given beside it, in the text and the JSON, never in its place.
TEST_CASE("manipulandum: a conclusion moved by the tracking gives the reference estimate and the tracked one beside it") {
  PlanarPrepared prep;
  prep.tracking.switched = true;
  prep.tracking.share = 0.95;
  prep.tracking.rms_um = 140.0;
  prep.pem.available = true;
  prep.pem.d << 14.5, -9.7, -9.5, 6.0;
  prep.pem.k << 83.4, -110.5, -110.5, 352.2;
  prep.tracking.on_tracked.available = true;
  prep.tracking.on_tracked.d << 13.1, -10.0, -8.8, 6.5;
  prep.tracking.on_tracked.k << 97.0, -107.7, -107.7, 344.3;
  const LikelihoodStage st;
  const auto c = conclude(Diagnosis{}, st, prep);
  REQUIRE(c.has_corrected);
  CHECK(c.corrected.d == prep.pem.d);
  REQUIRE(c.has_tracked);
  CHECK(c.tracked.k == prep.tracking.on_tracked.k);
  const auto text = conclusion_text(c, Diagnosis{});
  CHECK(text.find("apparatus: the stages lag the admittance reference") != std::string::npos);
  CHECK(text.find("corrected impedance (on the reference): D [14.5 -9.7; -9.5 6] N s/m, K [83.4 -110.5; -110.5 352.2] N/m") !=
        std::string::npos);
  CHECK(text.find("--position-source tracked): D [13.1 -10; -8.8 6.5] N s/m, K [97 -107.7; -107.7 344.3] N/m") != std::string::npos);
  const auto j = conclusion_json(c);
  CHECK(j["tracking"] == true);
  CHECK(j["corrected"]["k_npm"][0][0] == 83.4);
  CHECK(j["tracked"]["k_npm"][0][0] == 97.0);
  CHECK(j["tracked"]["d_nspm"][1][0] == -8.8);
  // Without the tracked fit (no likelihood method): no tracked estimate.
  prep.tracking.on_tracked.available = false;
  const auto c2 = conclude(Diagnosis{}, st, prep);
  CHECK_FALSE(c2.has_tracked);
  CHECK_FALSE(conclusion_json(c2).contains("tracked"));
  CHECK(conclusion_text(c2, Diagnosis{}).find("--position-source tracked") == std::string::npos);
}
