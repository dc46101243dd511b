// Hidden-mechanism sessions (include/manip/sim/hidden_effects.hpp, issue 11):
// each mechanism moves the default estimate in the direction the issue
// measured on main, and the log carries no trace of the generator's settings.
#include <catch2/catch.hpp>

#include <cmath>
#include <optional>
#include <sstream>

#include "manip/common/errors.hpp"
#include "manip/estimation/session_estimator.hpp"
#include "manip/estimation/trial_data.hpp"
#include "manip/sim/hidden_effects.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"
#include "mat_text.hpp"

using namespace manip;
using namespace manip::sim;
using sim_test::show;

namespace {

struct Result {
  Mat2 d{Mat2::Zero()}, k{Mat2::Zero()};     // pem, pooled
  Mat2 d_true{Mat2::Zero()}, k_true{Mat2::Zero()};  // intrinsic truth, mean
  std::string session_yaml, session_id;
  std::optional<ApparentImpedance> apparent;
};

Result run(const std::vector<HiddenEffect>& effects, std::uint64_t hidden_seed) {
  auto base = testutil::small_design(12);
  base.reps_per_angle = 1;
  auto person = table1_person();
  apply_noise(NoiseLevel::realistic, base, person);
  auto hs = make_hidden_session(base, person, effects, hidden_seed);
  std::vector<estimation::TrialData> trials;
  estimation::TrialAssembler asmb(
      [&](const estimation::SessionInfo&, estimation::TrialData&& t) { trials.push_back(std::move(t)); });
  const auto sum = run_session(hs.design, *hs.person, asmb);
  asmb.finish();
  estimation::EstimatorSettings s;
  s.methods = {"pem"};
  estimation::SessionEstimator est(s);
  for (auto t : trials) est.add_trial(asmb.session(), std::move(t));
  const auto r = est.finish(asmb.issues(), {});
  Result out;
  for (const auto& sm : r.summaries)
    if (sm.method == "pem" && sm.group.is_session()) {
      out.d = sm.d_nspm;
      out.k = sm.k_npm;
    }
  out.d_true = r.truth.d_nspm;
  out.k_true = r.truth.k_npm;
  out.session_yaml = asmb.session().config_yaml;
  out.session_id = asmb.session().session_id;
  out.apparent = sum.apparent;
  return out;
}

}  // namespace

TEST_CASE("hidden effects: parse MECHANISM:MAGNITUDE, refuse bad text with a message naming it") {
  const auto e = parse_hidden_effect("handle:0.3");
  CHECK(e.mechanism == HiddenMechanism::handle_mass);
  CHECK(e.magnitude == 0.3);
  CHECK(parse_hidden_effect("delay:0.002").mechanism == HiddenMechanism::actuation_delay);
  CHECK(parse_hidden_effect("friction:1").mechanism == HiddenMechanism::stage_friction);
  CHECK(parse_hidden_effect("reflex:0.5").mechanism == HiddenMechanism::reflex);
  CHECK(parse_hidden_effect("feedback:0.5").mechanism == HiddenMechanism::feedback);
  CHECK(parse_hidden_effect("reflex_dir:1").mechanism == HiddenMechanism::reflex_dir);
  CHECK(parse_hidden_effect("curl:40").mechanism == HiddenMechanism::curl);
  for (const char* bad : {"handle", "handle:", "handle:abc", "handle:0.3x", "mass:0.3", "delay:2", "curl:-40", "curl:nan"}) {
    INFO(bad);
    CHECK_THROWS_AS(parse_hidden_effect(bad), UsageError);
    try {
      (void)parse_hidden_effect(bad);
    } catch (const UsageError& err) {
      CHECK(std::string(err.what()).find(bad) != std::string::npos);
    }
  }
}

TEST_CASE("hidden effects: each mechanism shifts the default (pem) estimate the way the issue measured") {
  const std::uint64_t seed = 3;
  static const auto clean = run({}, seed);  // once for all sections
  INFO("clean: D " << show(clean.d) << " K " << show(clean.k) << " truth K " << show(clean.k_true));
  const auto rel = [](const Mat2& a, const Mat2& b, int i, int j) { return (a(i, j) - b(i, j)) / std::abs(b(i, j)); };
  SECTION("handle +0.3 kg: K11 lower, D11 higher") {
    const auto h = run({parse_hidden_effect("handle:0.3")}, seed);
    INFO("handle: D " << show(h.d) << " K " << show(h.k));
    CHECK(rel(h.k, clean.k, 0, 0) < -0.2);
    CHECK(rel(h.d, clean.d, 0, 0) > 0.1);
    CHECK((h.k_true - clean.k_true).norm() < 1e-9);  // the person is the same
    // The handle is apparatus: the apparent truth (person's) does not move.
    REQUIRE((h.apparent && clean.apparent));
    CHECK((h.apparent->k_npm - clean.apparent->k_npm).norm() < 0.01 * clean.apparent->k_npm.norm());
    CHECK((h.apparent->d_nspm - clean.apparent->d_nspm).norm() < 0.01 * clean.apparent->d_nspm.norm());
    // Nothing in the log's session message tells the hidden effect.
    CHECK(h.session_yaml == clean.session_yaml);
    CHECK(h.session_id == clean.session_id);
  }
  SECTION("actuation delay 2 ms: K11 higher, D22 lower") {
    const auto h = run({parse_hidden_effect("delay:0.002")}, seed);
    INFO("delay: D " << show(h.d) << " K " << show(h.k));
    CHECK(rel(h.k, clean.k, 0, 0) > 0.2);
    CHECK(rel(h.d, clean.d, 1, 1) < -0.2);
  }
  SECTION("stage friction 1 N: K11 and D11 higher") {
    const auto h = run({parse_hidden_effect("friction:1")}, seed);
    INFO("friction: D " << show(h.d) << " K " << show(h.k));
    // Measured +15 % on this short session (the issue: +149 % on 100
    // movements); the friction also shows as damping along x1.
    CHECK(rel(h.k, clean.k, 0, 0) > 0.1);
    CHECK(rel(h.d, clean.d, 0, 0) > 0.3);
    // Friction is apparatus: the apparent truth stays the person's (measured
    // 1.2 %: friction moves the onset postures, and M_BSP there differs from
    // the person's constant inertia; the clean session's own part of that is 3 N/m).
    REQUIRE((h.apparent && clean.apparent));
    CHECK((h.apparent->k_npm - clean.apparent->k_npm).norm() < 0.02 * clean.apparent->k_npm.norm());
  }
  SECTION("reflex 0.5 K at 25-35 ms: D22 lower, K changes by more than 20 %") {
    const auto h = run({parse_hidden_effect("reflex:0.5")}, seed);
    INFO("reflex: D " << show(h.d) << " K " << show(h.k));
    CHECK(rel(h.d, clean.d, 1, 1) < -0.1);
    CHECK(std::abs(rel(h.k, clean.k, 0, 0)) > 0.2);
  }
  SECTION("early feedback 1.0 K at 60-100 ms: the apparent K holds it, the intrinsic truth does not move") {
    const auto h = run({parse_hidden_effect("feedback:1")}, seed);
    INFO("feedback: D " << show(h.d) << " K " << show(h.k));
    CHECK((h.k_true - clean.k_true).norm() < 1e-9);  // the person's own D, K
    // A delayed copy g [D Δẋ + K Δx](t − τ) acting for the last 50-90 ms of
    // the window: the constant K that fits the window grows (hidden seed 1,
    // 100 movements: K11 +46 % over the intrinsic).
    REQUIRE((h.apparent && clean.apparent));
    CHECK(h.apparent->k_npm(0, 0) > 1.15 * clean.apparent->k_npm(0, 0));
    CHECK(h.apparent->k_npm(1, 1) > 1.05 * clean.apparent->k_npm(1, 1));
  }
  SECTION("curl 40 N/m: K12 error positive (relative to a negative K12: more negative)") {
    const auto h = run({parse_hidden_effect("curl:40")}, seed);
    INFO("curl: D " << show(h.d) << " K " << show(h.k));
    // The symmetric fit cannot hold an antisymmetric K, so K12 moves by what
    // the rest of the fit absorbs: measured -12 % here (realistic noise), +29 %
    // noise-free, +32 % in the issue (100 movements). Only the size is stable.
    CHECK(std::abs(rel(h.k, clean.k, 0, 1)) > 0.1);
    // The apparent truth (unconstrained D, K) holds the curl: its
    // antisymmetric part is the hidden [0 40; -40 0] N/m.
    REQUIRE(h.apparent);
    const double curl = 0.5 * (h.apparent->k_npm(0, 1) - h.apparent->k_npm(1, 0));
    INFO("apparent K " << show(h.apparent->k_npm));
    // Tolerance 10 %: the clean session's apparent K is itself 3.2 N/m
    // antisymmetric (the bowed reaches put the onset where M_BSP differs from
    // the person's constant inertia; the mismatch lands in D, K).
    CHECK(std::abs(curl - 40.0) < 0.10 * 40.0);
    REQUIRE(clean.apparent);
    CHECK(std::abs(0.5 * (clean.apparent->k_npm(0, 1) - clean.apparent->k_npm(1, 0))) < 0.10 * 40.0);
  }
}

// The direction-dependent reflex against its law, sample by sample: a group
// along w that a displacement along w stretches pulls back along −w with g ×
// the intrinsic K, D of the deviation one delay ago, w min(0, wᵀ[K e + D ė]);
// displaced against w (shortened) it adds nothing. The hand is driven at a
// constant acceleration while the plan holds still (reach onset after 10 s).
TEST_CASE("hidden effects: the direction-dependent reflex acts along w, one delay late, only when stretched") {
  LinearHumanParams person;  // no motor noise
  HiddenDraw draw;
  draw.reflex_delay_s = 0.030;
  draw.reflex_direction_rad = 2.0;  // w = (cos 2, sin 2)
  const double step_s = 1.0 / 16000.0, g = 0.8;
  const Vec2 w(std::cos(2.0), std::sin(2.0));
  ReachSpec reach;
  reach.t_start_s = 10.0;
  const auto lag = static_cast<std::size_t>(std::lround(draw.reflex_delay_s / step_s));
  for (const double sign : {1.0, -1.0}) {
    // Along ±w, turned by 0.3 rad so the deviation is not exactly on the line.
    const Vec2 dir = sign * Vec2(std::cos(2.3), std::sin(2.3));
    HiddenEffectHuman clean(person, {}, draw, step_s), dirr(person, {{HiddenMechanism::reflex_dir, g}}, draw, step_s);
    clean.begin_trial(reach, 7);
    dirr.begin_trial(reach, 7);
    std::vector<Vec2> x, v;
    const std::size_t n = 1600;  // 100 ms
    for (std::size_t k = 0; k < n; ++k) {
      x.push_back(dirr.hand_position_m());
      v.push_back(dirr.hand_velocity_mps());
      clean.advance(step_s, 2.0 * dir);
      dirr.advance(step_s, 2.0 * dir);
    }
    Mat2 m;
    Vec2 h_clean, h_dir;
    clean.endpoint_dynamics(m, h_clean);
    dirr.endpoint_dynamics(m, h_dir);
    // The oldest ring entry: the state after n − lag advances.
    const Vec2 e = reach.start_shoulder_m - x[n - lag], ed = -v[n - lag];
    const Vec2 copy = g * (person.k_npm * e + person.d_nspm * ed);
    const Vec2 want = w * std::min(0.0, w.dot(copy));
    INFO("sign " << sign << ": reflex force " << (h_dir - h_clean).transpose() << ", law " << want.transpose());
    CHECK((h_dir - h_clean - want).norm() < 1e-9 + 1e-6 * copy.norm());
    if (sign > 0) {
      CHECK(want.norm() > 0.1);            // stretched: it acts (N)
      CHECK(want.dot(w) < 0.0);            // and pulls back against w
    } else {
      CHECK((h_dir - h_clean).norm() == 0.0);  // shortened: nothing
    }
  }
}
