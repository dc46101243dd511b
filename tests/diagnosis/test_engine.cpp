// Hidden effects that the diagnosis must find (issue 11): one synthetic
// record per mechanism at the middle magnitude plus a clean one. The
// detection study over seeds and magnitudes is the [.study] case (not in CI);
// its results are in docs/diagnosis.md.
#include <unistd.h>

#include <catch2/catch.hpp>
#include <cmath>
#include <cstdio>
#include <algorithm>
#include <cstdlib>
#include <limits>
#include <map>
#include <numeric>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "diag_test_util.hpp"
#include "manip/common/errors.hpp"
#include "manip/diagnosis/report.hpp"
#include "manip/diagnosis/torque_lag.hpp"

using namespace manip::diagnosis;
using manip::diagnosis::test::rel_err;
using manip::diagnosis::test::run_synthetic;

namespace {
constexpr double kMiddle = 0.15;  // hidden torque RMS / intrinsic torque RMS (docs/diagnosis.md)

// A synthetic record through the diagnosis and then the torque-lag fit.
struct LagRun {
  synthetic::Generated g;
  Diagnosis d;
  TorqueLagFit f;
};
LagRun run_lag(const synthetic::Options& o, int bootstrap) {
  LagRun r{synthetic::generate(o), {}, {}};
  const auto prep = prepare_single_joint(r.g.record);
  EngineOptions eo;
  eo.bootstrap = bootstrap;
  const auto lib = standard_library();
  r.d = diagnose(prep.data, lib, eo);
  r.f = fit_torque_lag(prep.data, r.d, lib, eo);
  return r;
}
// Adds a reflex term gain_pos LP[v+] + gain_neg LP[v-] (positive = resists
// stretch) to the prepared target, built with the library's own columns at
// the grid point nearest to delay 45 ms, f_n 3.2 Hz, zeta 0.75, so that the
// engine can fit it exactly.
void add_reflex_term(SingleJointPrepared& prep, const Mechanism& reflex, double gain_pos, double gain_neg) {
  const std::vector<double> want{0.045, 3.2, 0.75};
  const auto grid = reflex.grid(prep.data);
  const auto setting = *std::min_element(grid.begin(), grid.end(), [&](const auto& p, const auto& q) {
    double dp = 0, dq = 0;
    for (std::size_t i = 0; i < want.size(); ++i) {
      dp += std::pow((p[i] - want[i]) / want[i], 2);
      dq += std::pow((q[i] - want[i]) / want[i], 2);
    }
    return dp < dq;
  });
  const auto cols = reflex.columns(prep.data, setting);
  auto& seg = prep.data.segments.front();
  for (std::size_t i = 0; i < seg.y.size(); ++i) seg.y[i] += gain_pos * cols.front()[0][i] + gain_neg * cols.front()[1][i];
}
double lag_param(const TorqueLagFit& f, const char* name) {
  for (const auto& q : f.params)
    if (q.name == name) return q.est.value;
  return std::numeric_limits<double>::quiet_NaN();
}
}  // namespace

TEST_CASE("clean record: no significant misfit", "[diagnosis][engine]") {
  synthetic::Options o;
  o.hidden = synthetic::Hidden::none;
  o.seed = 101;
    const auto r = run_synthetic(o);
  CHECK_FALSE(r.diag.misfit_found());
  // The baseline is the right model: its held-out gain test had nothing to accept,
  // and the intrinsic parameters are those of the generator.
  REQUIRE(r.diag.find_final("K"));
  CHECK(rel_err(r.diag.find_final("K")->est.value, r.truth.K) < 0.05);
  CHECK(rel_err(r.diag.find_final("B")->est.value, r.truth.B) < 0.20);
  CHECK(rel_err(r.diag.find_final("I")->est.value, r.truth.I) < 0.10);
}

TEST_CASE("each hidden mechanism at the middle magnitude is found, named first and measured", "[diagnosis][engine]") {
  const synthetic::Hidden hs[] = {synthetic::Hidden::reflex, synthetic::Hidden::quadratic_stiffness,
                                  synthetic::Hidden::offset_drift, synthetic::Hidden::friction};
  for (const auto h : hs) {
    DYNAMIC_SECTION(synthetic::name(h)) {
      synthetic::Options o;
      o.hidden = h;
      o.magnitude = kMiddle;
      o.seed = 7;
      const auto r = run_synthetic(o);
      const auto& d = r.diag;
      INFO("truth K " << r.truth.K << " B " << r.truth.B << " main " << r.truth.main_param(h));
      REQUIRE(d.misfit_found());
      CHECK(d.accepted.front() == synthetic::name(h));
      const auto* mp = d.find_final(synthetic::main_param_name(h));
      REQUIRE(mp);
      INFO("estimated main parameter " << mp->est.value);
      CHECK(rel_err(mp->est.value, r.truth.main_param(h)) < 0.20);
      CHECK(d.heldout_gain.value > 0.0);
      CHECK(d.heldout_gain.lo > 0.0);
      CHECK(rel_err(d.find_final("K")->est.value, r.truth.K) < 0.10);
      CHECK(rel_err(d.find_final("B")->est.value, r.truth.B) < 0.20);
      if (h == synthetic::Hidden::reflex) {  // the gain of the stretched direction too
        const auto* g = d.find_final(r.truth.reflex_dir > 0 ? "gain_pos_vel" : "gain_neg_vel");
        REQUIRE(g);
        INFO("reflex gain " << g->est.value << " truth " << r.truth.reflex_gain);
        CHECK(rel_err(g->est.value, r.truth.reflex_gain) < 0.30);
      }
    }
  }
}

// The relaxation's term is mostly along K x: only its slow part (the static
// stiffness below the fast one) tells it apart, in the band of the tonic
// contraction's 1 Hz fluctuation. Its detection limit is 0.8 (dK about 0.8 K:
// docs/diagnosis.md, "Detection study"), so its CI record is at that
// magnitude, not the middle one. There tau is within 20 % in 18/20 records.
TEST_CASE("a hidden stiffness relaxation at its detection limit is named, tau within 20 %, static K and K + dK measured", "[diagnosis][engine]") {
  synthetic::Options o;
  o.hidden = synthetic::Hidden::relaxation;
  o.magnitude = 0.8;
  o.seed = 2000;  // the study's first seed; seed 7, the other mechanisms' record, misses (tau +26 %), as 2 of the study's 20 do
  const auto r = run_synthetic(o);
  const auto& d = r.diag;
  INFO("truth K " << r.truth.K << " dK " << r.truth.dK << " tau " << r.truth.tau_relax_s);
  REQUIRE(d.misfit_found());
  CHECK(d.accepted.front() == "stiffness_relaxation");
  REQUIRE(d.find_final("tau_relax"));
  INFO("tau " << d.find_final("tau_relax")->est.value);
  CHECK(rel_err(d.find_final("tau_relax")->est.value, r.truth.tau_relax_s) < 0.20);
  CHECK(d.heldout_gain.lo > 0.0);
  CHECK(rel_err(d.find_final("K")->est.value, r.truth.K) < 0.10);
  CHECK(rel_err(d.find_final("B")->est.value, r.truth.B) < 0.20);
  // The stiffness to fast motion, K + dK, is reported beside the static K.
  REQUIRE(d.derived_params.size() == 1);
  const auto& kf = d.derived_params.front().param;
  INFO("K_fast " << kf.est.value << " [" << kf.est.lo << ", " << kf.est.hi << "]");
  CHECK(kf.name == "K_fast");
  CHECK(d.derived_params.front().base == "K");
  CHECK(rel_err(kf.est.value, r.truth.K + r.truth.dK) < 0.10);
  CHECK(kf.est.lo <= kf.est.value);
  CHECK(kf.est.value <= kf.est.hi);
  // Both reports carry it: the JSON's final.derived and the text's before -> after block.
  const auto j = json_report(d, ReportContext{});
  REQUIRE(j["final"]["derived"].size() == 1);
  CHECK(j["final"]["derived"][0]["name"] == "K_fast");
  CHECK(j["final"]["derived"][0]["base"] == "K");
  CHECK(j["final"]["derived"][0]["value"].get<double>() == Approx(kf.est.value));
  CHECK(j["final"]["derived"][0]["ci95"][0].get<double>() == Approx(kf.est.lo));
  CHECK(text_report(d, ReportContext{}).find("K_fast = K + dK") != std::string::npos);
}

// EngineOptions::require_physical: a reflex term whose unstretched
// direction clearly pushes the same way as its stretched one (a
// direction-blind term) is refused; one that leaks a little below 0, as a
// true reflex with its low pass off the grid does, is named. The term is
// added to a clean record's target with the library's own columns at a grid
// point, so the fitted gains are the ones added up to noise: the test is of
// the decision rule, not of the columns (those have their analytic tests).
TEST_CASE("a reflex term with a wrong-sign gain beyond its interval and above a quarter of the other is refused, a smaller one is named", "[diagnosis][engine]") {
  synthetic::Options o;
  o.seed = 41;
  const auto g = synthetic::generate(o);
  const auto lib = standard_library();
  const Mechanism* reflex = test::mechanism_by_id(lib, "stretch_reflex");
  REQUIRE(reflex);
  for (const double ratio : {0.5, 0.2}) {
    auto prep = prepare_single_joint(g.record);
    // gain_pos_vel 8 resists positive stretch; gain_neg_vel -8 ratio pushes with negative motion.
    add_reflex_term(prep, *reflex, 8.0, -8.0 * ratio);
    EngineOptions eo;
    eo.bootstrap = 20;
    const auto d = diagnose(prep.data, lib, eo);
    REQUIRE_FALSE(d.rounds.empty());
    const CandidateScore* c = nullptr;
    for (const auto& k : d.rounds.front().candidates)
      if (k.id == "stretch_reflex") c = &k;
    REQUIRE(c);
    INFO("ratio " << ratio << ": gains " << c->params[3].est.value << ", " << c->params[4].est.value << " SE " << c->gain_se[1]);
    CHECK(c->significant);
    CHECK(c->params[4].est.value + 1.96 * c->gain_se[1] < 0.0);  // the wrong sign beyond its interval either way
    if (ratio > 0.25) {
      CHECK(c->implausible);
      CHECK((d.accepted.empty() || d.accepted.front() != "stretch_reflex"));
    } else {
      CHECK_FALSE(c->implausible);
      REQUIRE(d.misfit_found());
      CHECK(d.accepted.front() == "stretch_reflex");
    }
  }
}

// Two mechanisms with shape grids: the second one's shape gets its interval
// from its own search in the bootstrap replicates (the first one's from the
// replicates that also give the gains), both containing the truth.
TEST_CASE("a relaxation and a reflex in one record - both named, each shape with a bootstrap interval, tau around the truth, the delay within 5 %", "[diagnosis][engine]") {
  synthetic::Options o;
  o.hidden = synthetic::Hidden::relaxation;
  o.magnitude = 0.8;
  o.seed = 2000;
  const auto g = synthetic::generate(o);
  auto prep = prepare_single_joint(g.record);
  const auto lib = standard_library();
  const Mechanism* reflex = test::mechanism_by_id(lib, "stretch_reflex");
  REQUIRE(reflex);
  add_reflex_term(prep, *reflex, 10.0, 0.0);
  EngineOptions eo;
  eo.bootstrap = 50;
  const auto d = diagnose(prep.data, lib, eo);
  REQUIRE(d.accepted.size() >= 2);
  CHECK(std::find(d.accepted.begin(), d.accepted.end(), "stretch_reflex") != d.accepted.end());
  CHECK(std::find(d.accepted.begin(), d.accepted.end(), "stiffness_relaxation") != d.accepted.end());
  const auto* delay = d.find_final("delay");
  const auto* tau = d.find_final("tau_relax");
  REQUIRE(delay);
  REQUIRE(tau);
  INFO("delay " << delay->est.value << " [" << delay->est.lo << ", " << delay->est.hi << "], tau " << tau->est.value << " [" << tau->est.lo
                << ", " << tau->est.hi << "] truth " << g.truth.tau_relax_s);
  for (const auto* q : {delay, tau}) {
    CHECK(q->est.lo < q->est.hi);  // re-searched, not a fixed value
    CHECK(q->est.lo <= q->est.value);
    CHECK(q->est.value <= q->est.hi);
  }
  // The reflex term sits on a grid point (45 ms, f_n 3.22 Hz, zeta 0.75),
  // but its delay trades against its low pass along a ridge, and off the
  // grid the noise moves the optimum along it: here 46.8 ms [45.5, 47.7],
  // where an exhaustive search on a grid 16 times finer in f_n and 10 times
  // in zeta around the truth finds 47.0 ms [45.5, 50.0] (a throwaway check,
  // 2026-12-06). The block bootstrap's interval is narrower than that ridge
  // ("Shape estimates and their intervals" in docs/diagnosis.md), so the
  // delay is checked against the truth with a tolerance, not by its interval.
  CHECK(rel_err(delay->est.value, 0.045) < 0.05);
  CHECK(tau->est.lo <= g.truth.tau_relax_s);
  CHECK(g.truth.tau_relax_s <= tau->est.hi);

  // One model: each mechanism's reported shape is the one its columns are
  // built from (Diagnosis::shape_of), and the reported gains are those of a
  // least-squares fit of the baseline and every named mechanism at those
  // shapes - here an independent fit over every sample past the library's
  // history, where the engine fits its blocks (so within 1 %, not exactly).
  REQUIRE(d.final_settings.size() == d.accepted.size());
  const auto& seg = prep.data.segments.front();
  std::size_t history = 0;
  for (const auto& m : lib) history = std::max(history, m->history_samples(prep.data));
  std::vector<const std::vector<double>*> cols;
  for (const auto& c : seg.base) cols.push_back(&c);
  std::vector<Columns> named;
  named.reserve(d.accepted.size());
  std::vector<std::string> gain_names;
  for (std::size_t a = 0; a < d.accepted.size(); ++a) {
    const auto* m = test::mechanism_by_id(lib, d.accepted[a]);
    REQUIRE(m);
    const auto sp = m->shape_params();
    REQUIRE(d.shape_of(a).size() == sp.size());
    for (std::size_t i = 0; i < sp.size(); ++i) {
      REQUIRE(d.find_final(sp[i].name));
      CHECK(d.shape_of(a)[i] == d.find_final(sp[i].name)->est.value);
    }
    named.push_back(m->columns(prep.data, d.shape_of(a)));
    for (const auto& c : named.back().front()) cols.push_back(&c);
    for (const auto& gi : m->gains()) gain_names.push_back(gi.name);
  }
  CHECK(d.shape_of(0) != d.accepted_settings[0]);  // searched off the grid
  const auto n = static_cast<Eigen::Index>(seg.y.size() - history);
  Eigen::MatrixXd X(n, static_cast<Eigen::Index>(cols.size()));
  for (std::size_t j = 0; j < cols.size(); ++j)
    X.col(static_cast<Eigen::Index>(j)) = Eigen::Map<const Eigen::VectorXd>(cols[j]->data() + history, n);
  const Eigen::VectorXd th = X.colPivHouseholderQr().solve(Eigen::Map<const Eigen::VectorXd>(seg.y.data() + history, n));
  const auto p0 = static_cast<Eigen::Index>(seg.base.size());
  for (std::size_t k = 0; k < gain_names.size(); ++k) {
    const double reported = d.find_final(gain_names[k])->est.value, fitted = th(p0 + static_cast<Eigen::Index>(k));
    INFO(gain_names[k] << " reported " << reported << ", fitted at the reported shapes " << fitted);
    CHECK(std::fabs(reported - fitted) < 0.01 * std::fabs(fitted) + 0.02);
  }
}

// The reflex's shapes are searched on a grid (delay 1 ms, f_n ratio 1.34,
// zeta in {0.5, 0.75, 1}), then off it on a finer lattice (engine.cpp,
// LatticeSearch). Seed 2006 at 0.8 (a study record) has its truth between
// the grid's points: zeta 0.656, whose nearest grid values 0.75 and 0.5 are
// 14 % and 24 % off; f_n 4.38 Hz between 4.32 and 5.78.
TEST_CASE("a reflex whose low pass lies between grid points - shapes refined between them, each with an interval", "[diagnosis][engine]") {
  synthetic::Options o;
  o.hidden = synthetic::Hidden::reflex;
  o.magnitude = 0.8;
  o.seed = 2006;
  const auto r = run_synthetic(o, 20);
  const auto& d = r.diag;
  INFO("truth delay " << r.truth.delay_s << " fn " << r.truth.fn_hz << " zeta " << r.truth.zeta);
  REQUIRE(d.misfit_found());
  CHECK(d.accepted.front() == "stretch_reflex");
  const auto* delay = d.find_final("delay");
  const auto* fn = d.find_final("fn");
  const auto* zeta = d.find_final("zeta");
  REQUIRE(delay);
  REQUIRE(fn);
  REQUIRE(zeta);
  INFO("delay " << delay->est.value << " fn " << fn->est.value << " [" << fn->est.lo << ", " << fn->est.hi << "] zeta " << zeta->est.value);
  CHECK(rel_err(zeta->est.value, r.truth.zeta) < 0.07);  // no grid value is within 14 %
  CHECK(rel_err(fn->est.value, r.truth.fn_hz) < 0.05);
  CHECK(rel_err(delay->est.value, r.truth.delay_s) < 0.05);
  // Off the grid: the grid's delays are whole milliseconds.
  CHECK(std::fabs(delay->est.value * 1e3 - std::round(delay->est.value * 1e3)) > 1e-6);
  for (const auto* q : {delay, fn, zeta}) {
    CHECK(q->est.lo < q->est.hi);  // not collapsed onto one grid point
    CHECK(q->est.lo <= q->est.value);
    CHECK(q->est.value <= q->est.hi);
  }
}

TEST_CASE("a wrong configured inertia is named when the baseline fixes it", "[diagnosis][engine]") {
  synthetic::Options o;
  o.seed = 31;
  const auto g = synthetic::generate(o);
  SingleJointOptions sj;
  sj.inertia_fixed = true;
  sj.fixed_inertia_kgm2 = g.truth.I + 0.01;  // configured 10 g m^2 too heavy: dI = -0.01 kg m^2
  const auto prep = prepare_single_joint(g.record, sj);
  EngineOptions eo;
  eo.bootstrap = 50;
  const auto d = diagnose(prep.data, standard_library(), eo);
  REQUIRE(d.misfit_found());
  CHECK(d.accepted.front() == "wrong_inertia");
  REQUIRE(d.find_final("dI"));
  CHECK(d.find_final("dI")->est.value == Approx(-0.01).epsilon(0.2));
  CHECK(test::rel_err(d.find_final("K")->est.value, g.truth.K) < 0.10);
  CHECK(test::rel_err(d.find_final("B")->est.value, g.truth.B) < 0.20);
}

TEST_CASE("engine API: a dataset of many segments (trials) is cross-validated by groups of segments", "[diagnosis][engine]") {
  // The manipulandum front end will hand over one segment per trial; here a
  // reflex record is cut into 12 separate 6 s segments, each with its own
  // smoothing and history, and the folds group neighbouring segments.
  synthetic::Options o;
  o.hidden = synthetic::Hidden::reflex;
  o.magnitude = 0.4;
  o.seed = 3;
  o.duration_s = 72.0;
  const auto g = synthetic::generate(o);
  Dataset d;
  const std::size_t per = g.record.pos_rad.size() / 12;
  for (std::size_t k = 0; k < 12; ++k) {
    SingleJointRecord piece;
    piece.source = "piece";
    piece.dt_s = g.record.dt_s;
    piece.pos_rad.assign(g.record.pos_rad.begin() + static_cast<long>(k * per), g.record.pos_rad.begin() + static_cast<long>((k + 1) * per));
    piece.torque_nm.assign(g.record.torque_nm.begin() + static_cast<long>(k * per), g.record.torque_nm.begin() + static_cast<long>((k + 1) * per));
    SingleJointOptions sj;
    sj.torque_sign = g.truth.torque_sign;
    auto prep = prepare_single_joint(piece, sj);
    prep.data.segments.front().t0_s = static_cast<double>(k * per) * g.record.dt_s;
    if (k == 0) {
      d = prep.data;
    } else {
      d.segments.push_back(prep.data.segments.front());
    }
  }
  d.source = "segments";
  EngineOptions eo;
  eo.bootstrap = 30;
  const auto r = diagnose(d, standard_library(), eo);
  CHECK(r.blocks == 12);
  REQUIRE(r.misfit_found());
  CHECK(r.accepted.front() == "stretch_reflex");
  CHECK(test::rel_err(r.find_final("delay")->est.value, g.truth.delay_s) < 0.20);
  CHECK(test::rel_err(r.find_final("K")->est.value, g.truth.K) < 0.10);
}

TEST_CASE("a record too short for cross-validation is refused with what is needed", "[diagnosis][engine]") {
  synthetic::Options o;
  o.duration_s = 8.0;
  const auto g = synthetic::generate(o);
  const auto prep = prepare_single_joint(g.record);
  try {
    (void)diagnose(prep.data, standard_library());
    FAIL("expected an InputError");
  } catch (const manip::InputError& e) {
    CHECK(std::string(e.what()).find("need at least") != std::string::npos);
    CHECK(e.exit_code() == manip::exit_code::kInput);
  }
}

// A lag of the torque channel is not a mechanism of the library: it moves
// B and I along the data's own directions (single_joint.hpp,
// single_joint_physical_checks). Against the first-order expansion
// tau / (1 + T s) = K x + (B - T K) s x + (I - T B + T^2 K) s^2 x + O(s^3):
// at T = 1 ms the baseline keeps K and moves B by -T K (the O(s^3) terms
// move it by less than 0.1 N m s/rad at this input's 12 Hz bandwidth:
// measured 2026-12-05, docs/diagnosis.md "Torque-channel lag").
TEST_CASE("a torque-channel lag moves the baseline B by -T K and keeps K", "[diagnosis][engine]") {
  synthetic::Options o;
  o.hidden = synthetic::Hidden::torque_lag;
  o.lag_s = 0.001;
  o.seed = 7;
  const auto r = run_synthetic(o);
  const auto* b = r.diag.find_baseline("B");
  const auto* k = r.diag.find_baseline("K");
  REQUIRE(b);
  REQUIRE(k);
  INFO("truth B " << r.truth.B << " K " << r.truth.K << "; baseline B " << b->est.value << " K " << k->est.value);
  CHECK(rel_err(k->est.value, r.truth.K) < 0.05);
  CHECK(std::fabs(b->est.value - (r.truth.B - o.lag_s * r.truth.K)) < 0.1);
  CHECK(std::fabs(b->est.value - r.truth.B) > 0.1);  // the shift itself is measured, not within the noise
}

TEST_CASE("a torque lag that makes B negative is reported with the least lag that explains it", "[diagnosis][engine]") {
  synthetic::Options o;
  o.hidden = synthetic::Hidden::torque_lag;
  o.magnitude = kMiddle;
  o.seed = 7;
  const auto r = run_synthetic(o);
  const auto checks = single_joint_physical_checks(r.diag);
  INFO("truth lag " << r.truth.lag_s << " B " << r.truth.B << "; baseline B " << r.diag.find_baseline("B")->est.value);
  REQUIRE(checks.size() >= 1);
  CHECK(checks.front().what == "B < 0");
  CHECK(checks.front().least_lag_s > 0.0);
  CHECK(checks.front().least_lag_s <= r.truth.lag_s);
  CHECK(checks.front().text.find("torque channel") != std::string::npos);
  // A clean record passes the checks.
  synthetic::Options c;
  c.seed = 101;
  CHECK(single_joint_physical_checks(run_synthetic(c).diag).empty());
}

TEST_CASE("a torque-channel lag is fitted by output error - T within 20 %, I, B, K at T - and none is found on a clean record", "[diagnosis][engine]") {
  for (const bool lagged : {true, false}) {
    synthetic::Options o;
    o.hidden = lagged ? synthetic::Hidden::torque_lag : synthetic::Hidden::none;
    o.magnitude = kMiddle;
    o.seed = lagged ? 7 : 101;
    const auto r = run_lag(o, 50);
    const auto& g = r.g;
    const auto& f = r.f;
    REQUIRE(f.done);
    INFO("lagged " << lagged << ": p " << f.test.p_value << " T " << f.lag_s.value << " truth " << g.truth.lag_s);
    CHECK(f.significant == lagged);
    if (!lagged) continue;
    CHECK(rel_err(f.lag_s.value, g.truth.lag_s) < 0.20);
    CHECK(rel_err(lag_param(f, "I"), g.truth.I) < 0.20);
    CHECK(rel_err(lag_param(f, "B"), g.truth.B) < 0.20);
    CHECK(rel_err(lag_param(f, "K"), g.truth.K) < 0.05);
    CHECK(torque_lag_text(f).find("SIGNIFICANT") != std::string::npos);
  }
}

// What the tool does with a torque-channel lag, over seeds and the study's
// magnitudes (docs/diagnosis.md, "Torque-channel lag"):
// build/tests/test_diagnosis "[.lagstudy]" -s
TEST_CASE("torque-lag study", "[.lagstudy]") {
  const int seeds = 20;
  std::printf("| magnitude | median lag, ms | nothing named | named first (ids) | K within 10 %% | B within 20 %%, baseline | B < 0 flagged | least lag <= truth | lag significant | lag within 20 %% | median T / truth | interval covers | B within 20 %% at T | I within 20 %% at T | K within 10 %% at T |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const double m : {0.0, 0.05, 0.15, 0.40}) {
    int none = 0, kok = 0, bok0 = 0, flagged = 0, bound_ok = 0, sig = 0, tok = 0, cover = 0, bl = 0, il = 0, kl = 0;
    std::vector<double> lags, ratio;
    std::map<std::string, int> first;
    for (int s = 0; s < seeds; ++s) {
      synthetic::Options o;
      o.hidden = m > 0 ? synthetic::Hidden::torque_lag : synthetic::Hidden::none;
      o.magnitude = m;
      o.seed = (m > 0 ? 2000 : 1000) + static_cast<std::uint64_t>(s);
      const auto r = run_lag(o, 100);
      const auto& d = r.d;
      const auto& f = r.f;
      const auto& t = r.g.truth;
      lags.push_back(t.lag_s * 1e3);
      if (d.misfit_found()) ++first[d.accepted.front()]; else ++none;
      kok += rel_err(d.find_final("K")->est.value, t.K) < 0.10;
      bok0 += rel_err(d.find_baseline("B")->est.value, t.B) < 0.20;
      for (const auto& c : single_joint_physical_checks(d))
        if (c.what == "B < 0") {
          ++flagged;
          bound_ok += c.least_lag_s <= t.lag_s;
        }
      if (!f.significant) continue;
      ++sig;
      if (t.lag_s > 0) {
        tok += rel_err(f.lag_s.value, t.lag_s) < 0.2;
        ratio.push_back(f.lag_s.value / t.lag_s);
        cover += f.lag_s.lo <= t.lag_s && t.lag_s <= f.lag_s.hi;
      }
      bl += rel_err(lag_param(f, "B"), t.B) < 0.2;
      il += rel_err(lag_param(f, "I"), t.I) < 0.2;
      kl += rel_err(lag_param(f, "K"), t.K) < 0.1;
    }
    std::sort(lags.begin(), lags.end());
    std::sort(ratio.begin(), ratio.end());
    std::string ids;
    for (const auto& [id, n] : first) ids += (ids.empty() ? "" : ", ") + id + " " + std::to_string(n);
    std::printf("| %.2f | %.2f | %d/%d | %s | %d/%d | %d/%d | %d/%d | %d/%d | %d/%d | %d/%d | %.3f | %d/%d | %d/%d | %d/%d | %d/%d |\n", m, lags[lags.size() / 2], none,
                seeds, ids.c_str(), kok, seeds, bok0, seeds, flagged, seeds, bound_ok, flagged, sig, seeds, tok, seeds,
                ratio.empty() ? NAN : ratio[ratio.size() / 2], cover, seeds, bl, sig, il, sig, kl, sig);
    std::fflush(stdout);
  }
  // A lag where there is none: records with another hidden mechanism (the
  // relaxation at its detection limit, 0.8; the others at the middle magnitude).
  std::printf("\n| hidden | lag significant |\n|---|---|\n");
  for (const auto h : {synthetic::Hidden::reflex, synthetic::Hidden::quadratic_stiffness, synthetic::Hidden::offset_drift,
                       synthetic::Hidden::friction, synthetic::Hidden::relaxation}) {
    int sig = 0;
    for (int s = 0; s < seeds; ++s) {
      synthetic::Options o;
      o.hidden = h;
      o.magnitude = h == synthetic::Hidden::relaxation ? 0.8 : kMiddle;
      o.seed = 2000 + static_cast<std::uint64_t>(s);
      sig += run_lag(o, 20).f.significant;
    }
    std::printf("| %s | %d/%d |\n", synthetic::name(h), sig, seeds);
    std::fflush(stdout);
  }
}

// Detection study (docs/diagnosis.md): 20 seeds per mechanism and magnitude,
// plus 20 clean records. Run: build/tests/test_diagnosis "[.study]" -s
TEST_CASE("detection study", "[.study]") {
  const synthetic::Hidden hs[] = {synthetic::Hidden::reflex, synthetic::Hidden::quadratic_stiffness,
                                  synthetic::Hidden::offset_drift, synthetic::Hidden::friction,
                                  synthetic::Hidden::relaxation};
  // MANIP_STUDY_ONLY=<mechanism id> runs that mechanism's rows only (no
  // clean row); MANIP_STUDY_MAGS="0.4,0.8" replaces the three magnitudes;
  // MANIP_STUDY_SHAPES=1 prints every named session's shape estimates with
  // their intervals and truths (stderr; the per-cell summary is always there).
  const char* only = std::getenv("MANIP_STUDY_ONLY");
  std::vector<double> mags{0.05, 0.15, 0.40};
  if (const char* m = std::getenv("MANIP_STUDY_MAGS")) {
    mags.clear();
    for (const char* p = m; *p;) {
      char* end = nullptr;
      mags.push_back(std::strtod(p, &end));
      if (end == p) break;
      p = *end == ',' ? end + 1 : end;
    }
  }
  const int seeds = 20;
  std::printf("| mechanism | magnitude | named first | main param within 20 %% | gain > 0 (CI) | K within 10 %% | B within 20 %% | median |main err| | median gain |\n|---|---|---|---|---|---|---|---|---|\n");
  if (!only) {
    int fa = 0, kok = 0, bok = 0;
    for (int s = 0; s < seeds; ++s) {
      synthetic::Options o;
      o.seed = 1000 + static_cast<std::uint64_t>(s);
      const auto r = run_synthetic(o, 100);
      fa += r.diag.misfit_found();
      kok += rel_err(r.diag.find_final("K")->est.value, r.truth.K) < 0.10;
      bok += rel_err(r.diag.find_final("B")->est.value, r.truth.B) < 0.20;
    }
    std::printf("| none (clean) | 0 | no false alarm %d/%d | | | %d/%d | %d/%d | | |\n", seeds - fa, seeds, kok, seeds, bok, seeds);
    std::fflush(stdout);
  }
  for (const auto h : hs)
    for (const double m : mags) {
      if (only && std::string(only) != synthetic::name(h)) continue;
      int first = 0, mp = 0, gain = 0, kok = 0, bok = 0;
      std::vector<double> errs, gains;
      // Every shape parameter of the hidden mechanism, over the named sessions:
      // relative errors and how often its bootstrap interval covers the truth.
      std::map<std::string, std::vector<double>> shape_err;
      std::map<std::string, int> shape_cover;
      for (int s = 0; s < seeds; ++s) {
        synthetic::Options o;
        o.hidden = h;
        o.magnitude = m;
        o.seed = 2000 + static_cast<std::uint64_t>(s);
        const auto r = run_synthetic(o, 100);
        const auto& d = r.diag;
        const bool named = d.misfit_found() && d.accepted.front() == synthetic::name(h);
        first += named;
        if (named && h == synthetic::Hidden::reflex) {  // the unstretched direction's gain against the stretched one's
          const auto* gs = d.find_final(r.truth.reflex_dir > 0 ? "gain_pos_vel" : "gain_neg_vel");
          const auto* gu = d.find_final(r.truth.reflex_dir > 0 ? "gain_neg_vel" : "gain_pos_vel");
          std::fprintf(stderr, "reflex %.2f seed %llu: unstretched/stretched gain %.3f\n", m, static_cast<unsigned long long>(o.seed),
                       gu->est.value / gs->est.value);
        }
        if (!named)  // what took its place (stderr: the table stays on stdout)
          std::fprintf(stderr, "%s %.2f seed %llu: %s\n", synthetic::name(h), m, static_cast<unsigned long long>(o.seed),
                       d.misfit_found() ? d.accepted.front().c_str() : "nothing named");
        if (named) {
          const auto& t = r.truth;
          const std::pair<const char*, double> shapes[] = {
              {"delay", t.delay_s}, {"fn", t.fn_hz}, {"zeta", t.zeta}, {"tau_relax", t.tau_relax_s}, {"v_s", t.v_s}};
          for (const auto& [nm, tv] : shapes)
            if (const auto* p = d.find_final(nm); p && tv > 0) {
              shape_err[nm].push_back(rel_err(p->est.value, tv));
              if (std::getenv("MANIP_STUDY_SHAPES"))  // every named session's shape estimates, one line each
                std::fprintf(stderr, "%s %.2f seed %llu shape %s: %.5g [%.5g, %.5g], truth %.5g\n", synthetic::name(h), m,
                             static_cast<unsigned long long>(o.seed), nm, p->est.value, p->est.lo, p->est.hi, tv);
              shape_cover[nm] += p->est.lo <= tv && tv <= p->est.hi;
            }
          const double e = rel_err(d.find_final(synthetic::main_param_name(h))->est.value, r.truth.main_param(h));
          errs.push_back(e);
          mp += e < 0.2;
        }
        gains.push_back(d.heldout_gain.value);
        gain += d.heldout_gain.lo > 0.0;
        kok += rel_err(d.find_final("K")->est.value, r.truth.K) < 0.10;
        bok += rel_err(d.find_final("B")->est.value, r.truth.B) < 0.20;
      }
      for (auto& [nm, e] : shape_err) {
        std::sort(e.begin(), e.end());
        std::fprintf(stderr, "%s %.2f shape %s: median |err| %.3f, mean %.3f, interval covers %d/%zu\n", synthetic::name(h), m, nm.c_str(),
                     e[e.size() / 2], std::accumulate(e.begin(), e.end(), 0.0) / static_cast<double>(e.size()), shape_cover[nm], e.size());
      }
      std::sort(errs.begin(), errs.end());
      std::sort(gains.begin(), gains.end());
      std::printf("| %s | %.2f | %d/%d | %d/%d | %d/%d | %d/%d | %d/%d | %.3f | %.4f |\n", synthetic::name(h), m, first, seeds, mp, seeds,
                  gain, seeds, kok, seeds, bok, seeds, errs.empty() ? NAN : errs[errs.size() / 2], gains[gains.size() / 2]);
      std::fflush(stdout);
    }
}

// Writes one synthetic record per mechanism (middle magnitude) for running
// diagnose_model by hand: MANIP_DIAG_DUMP=dir build/tests/test_diagnosis "[.dump]"
TEST_CASE("dump synthetic records", "[.dump]") {
  const char* dir = std::getenv("MANIP_DIAG_DUMP");
  REQUIRE(dir);
  const char* seed = std::getenv("MANIP_DIAG_SEED");
  for (const auto h : {synthetic::Hidden::none, synthetic::Hidden::reflex, synthetic::Hidden::quadratic_stiffness,
                       synthetic::Hidden::offset_drift, synthetic::Hidden::friction, synthetic::Hidden::torque_lag,
                       synthetic::Hidden::relaxation}) {
    synthetic::Options o;
    o.hidden = h;
    o.magnitude = kMiddle;
    o.seed = seed ? std::strtoull(seed, nullptr, 10) : 7;
    const auto g = synthetic::generate(o);
    synthetic::write_csv(g.record, std::string(dir) + "/" + synthetic::name(h) + ".csv", false);
    const auto& t = g.truth;
    std::printf("%s: I %.4g B %.4g K %.4g c %.4g sign %d delay %.4g fn %.3g zeta %.3g gain %.4g dir %d K2 %.4g drift %.4g Fc %.4g lag %.4g tau_relax %.4g dK %.4g\n",
                synthetic::name(h), t.I, t.B, t.K, t.c, t.torque_sign, t.delay_s, t.fn_hz, t.zeta, t.reflex_gain, t.reflex_dir, t.K2,
                t.drift_rate, t.Fc, t.lag_s, t.tau_relax_s, t.dK);
  }
}
