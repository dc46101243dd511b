// Protocol: schedule counts and randomisation, trial phases, abort/re-queue.
#include <catch2/catch.hpp>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <set>

#include "manip/control/protocol.hpp"
#include "manip/common/rng.hpp"
#include "manip/trial_event_t.hpp"
#include "test_support.hpp"

using manip::Vec2;
using namespace manip::control;
using namespace manip::runtime;

namespace {
int deg(double rad) { return static_cast<int>(std::lround(rad * 180.0 / std::numbers::pi)); }
}  // namespace

TEST_CASE("portable RNG reproduces SplitMix64", "[protocol][rng]") {
  manip::PortableRng r(0);
  CHECK(r.next() == 0xE220A8397B1DCDAFull);  // SplitMix64 reference output for seed 0
  CHECK(r.next() == 0x6E789E6AA1B965F4ull);
  manip::PortableRng a(42), b(42);
  for (int i = 0; i < 100; ++i) REQUIRE(a.below(7) == b.below(7));
  for (int i = 0; i < 1000; ++i) {
    const double u = a.uniform();
    REQUIRE((u >= 0.0 && u < 1.0));
  }
}

TEST_CASE("schedule: 100 movements, 24 perturbed, each angle 3 times, reproducible per seed", "[protocol]") {
  const RtConfig cfg;
  const auto s1 = make_schedule(cfg.protocol, cfg.perturbation, cfg.perturbed_count());
  REQUIRE(s1.size() == 100);
  std::map<int, int> per_angle;
  int n = 0;
  for (const auto& t : s1)
    if (t.perturbed) {
      ++n;
      ++per_angle[deg(t.angle_rad)];
    }
  CHECK(n == 24);
  REQUIRE(per_angle.size() == 8);
  for (int a : {30, 60, 120, 150, 210, 240, 300, 330}) CHECK(per_angle[a] == 3);

  const auto s2 = make_schedule(cfg.protocol, cfg.perturbation, cfg.perturbed_count());
  for (std::size_t i = 0; i < s1.size(); ++i) {
    REQUIRE(s1[i].perturbed == s2[i].perturbed);
    REQUIRE(s1[i].angle_rad == s2[i].angle_rad);
  }
  ProtocolConfig other = cfg.protocol;
  other.seed = cfg.protocol.seed + 1;
  const auto s3 = make_schedule(other, cfg.perturbation, cfg.perturbed_count());
  int differ = 0;
  for (std::size_t i = 0; i < s1.size(); ++i) differ += s1[i].perturbed != s3[i].perturbed;
  CHECK(differ > 0);
}

TEST_CASE("schedule: perturbed slots are uniformly placed and angle order is random across seeds", "[protocol]") {
  RtConfig cfg;
  std::vector<int> slot_count(100, 0);
  std::map<int, int> first_angle;
  const int seeds = 2000;
  for (int s = 0; s < seeds; ++s) {
    cfg.protocol.seed = static_cast<std::uint64_t>(s) * 7919u + 1u;
    const auto sch = make_schedule(cfg.protocol, cfg.perturbation, 24);
    bool first = true;
    for (std::size_t i = 0; i < sch.size(); ++i)
      if (sch[i].perturbed) {
        ++slot_count[i];
        if (first) ++first_angle[deg(sch[i].angle_rad)];
        first = false;
      }
  }
  // Each slot perturbed with probability 0.24: expected 480 of 2000, sd ~19.
  for (int c : slot_count) REQUIRE(std::abs(c - 480) < 5 * 19.1);
  // The first perturbed trial's angle is uniform over the 8 angles: 250 each, sd ~14.8.
  REQUIRE(first_angle.size() == 8);
  for (const auto& [a, c] : first_angle) REQUIRE(std::abs(c - 250) < 5 * 14.8);
}

TEST_CASE("schedule: a shortened session keeps the perturbed fraction", "[protocol][config]") {
  const RtConfig full = test_support::shipped_config();
  const auto ov = trials_overrides(full, 12);
  const RtConfig cfg = test_support::shipped_config(ov);
  CHECK(cfg.protocol.movements == 12);
  CHECK(cfg.perturbed_count() == 3);  // round(12 * 24 / 100)
  const auto s = make_schedule(cfg.protocol, cfg.perturbation, cfg.perturbed_count());
  CHECK(std::count_if(s.begin(), s.end(), [](const TrialSpec& t) { return t.perturbed; }) == 3);
  // the effective configuration text records the overrides and re-parses to the same session
  const RtConfig again = parse_rt_config(cfg.effective_yaml, "effective");
  CHECK(again.protocol.movements == 12);
  CHECK(again.perturbed_count() == 3);
}

namespace {

// Drives a Protocol with a teleporting participant: rests in start, jumps
// across the trigger towards the goal in a few cycles, rests in goal. Every
// `timeout_every`-th trial the participant never leaves the start (timeout).
struct Driver {
  RtConfig cfg;
  Protocol p;
  std::vector<TrialEventRecord> ev;
  std::int64_t k{0};
  explicit Driver(const RtConfig& c) : cfg(c), p(c) { p.begin(); }
  void step(const Vec2& x, const Vec2& v) {
    ProtocolEvents out;
    p.update(k, k * 250, x, v, out);
    for (int i = 0; i < out.n; ++i) ev.push_back(out.ev[static_cast<std::size_t>(i)]);
    ++k;
  }
  void run(int timeout_every, int max_trials) {
    const Vec2 s = cfg.protocol.start_shoulder_m, g = cfg.protocol.goal_shoulder_m;
    int trials = 0;
    while (!p.done() && trials < max_trials) {
      while (!p.trial_active() && !p.done()) step(s, Vec2::Zero());
      if (p.done()) break;
      const int idx = p.trial_index();
      ++trials;
      if (timeout_every > 0 && idx % timeout_every == timeout_every - 1) {
        while (p.trial_active()) step(s, Vec2::Zero());
        continue;
      }
      for (int i = 1; i <= 10; ++i) step(s + (g - s) * (i / 10.0), Vec2(0.0, 0.2));
      while (p.trial_active()) step(g, Vec2::Zero());
    }
  }
};

}  // namespace

TEST_CASE("protocol: 100 movements, every perturbation delivered once, aborted perturbed trials re-queued",
          "[protocol]") {
  RtConfig cfg;
  cfg.protocol.trial_timeout_s = 1.0;  // keep the timeouts short
  cfg.protocol.start_hold_s = 0.01;
  cfg.protocol.goal_hold_s = 0.01;
  Driver d(cfg);
  d.run(/*timeout_every=*/7, 1000);
  REQUIRE(d.p.done());
  const auto& n = d.p.counters();
  int starts = 0, onsets = 0, ends = 0, aborts = 0, perturbed_ends = 0, aborted_perturbed = 0;
  std::map<int, int> onset_angles;
  std::set<int> indices;
  for (const auto& e : d.ev) {
    switch (e.kind) {
      case manip::trial_event_t::START:
        ++starts;
        REQUIRE(indices.insert(e.trial).second);  // trial indices unique
        break;
      case manip::trial_event_t::ONSET:
        ++onsets;
        ++onset_angles[deg(e.pert_angle_rad)];
        break;
      case manip::trial_event_t::END:
        ++ends;
        perturbed_ends += e.perturbed;
        break;
      case manip::trial_event_t::ABORT:
        ++aborts;
        aborted_perturbed += e.perturbed;
        REQUIRE(e.reason == AbortReason::kTimeout);
        break;
    }
  }
  CHECK(starts == n.started);
  CHECK(ends + aborts == starts);
  CHECK(perturbed_ends == 24);  // every perturbed trial eventually done
  CHECK(onsets == 24);          // timeouts never left the start: no onset there
  for (int a : {30, 60, 120, 150, 210, 240, 300, 330}) CHECK(onset_angles[a] == 3);
  CHECK(aborted_perturbed == n.requeued);
  CHECK(n.dropped == 0);
  // 100 slots consumed: normal ends + aborted unperturbed slots (not repeated)
  CHECK(ends + (aborts - aborted_perturbed) == 100);
  CHECK(starts == 100 + n.requeued);
}

TEST_CASE("protocol: a perturbed trial aborted more than max_requeues times is dropped and reported", "[protocol]") {
  RtConfig cfg;
  cfg.protocol.movements = 2;
  cfg.protocol.perturbed_trials = 1;
  cfg.protocol.trial_timeout_s = 0.05;
  cfg.protocol.start_hold_s = 0.001;
  cfg.protocol.max_requeues = 2;
  Driver d(cfg);
  d.run(/*timeout_every=*/1, 100);  // never moves
  CHECK(d.p.done());
  CHECK(d.p.counters().requeued == 2);
  CHECK(d.p.counters().dropped == 1);
  CHECK(d.p.counters().started == 2 + 2);
  int dropped = 0;
  for (const auto& e : d.ev) dropped += e.dropped;
  CHECK(dropped == 1);
}

TEST_CASE("protocol: phases and the start/goal hold", "[protocol]") {
  RtConfig cfg;
  cfg.protocol.movements = 1;
  cfg.protocol.perturbed_trials = 0;
  Driver d(cfg);
  const Vec2 s = cfg.protocol.start_shoulder_m, g = cfg.protocol.goal_shoulder_m;
  // moving (not resting) in the start target: no start
  for (int i = 0; i < 4000; ++i) d.step(s, Vec2(0.0, 0.05));
  CHECK(d.p.phase() == Phase::kReturn);
  CHECK_FALSE(d.p.trial_active());
  // resting: START after exactly start_hold_s (2000 cycles)
  const std::int64_t k0 = d.k;
  while (!d.p.trial_active()) d.step(s, Vec2::Zero());
  CHECK(d.k - k0 == 2000);
  CHECK(d.p.phase() == Phase::kReach);
  CHECK(d.p.trial_index() == 0);
  d.step(g, Vec2::Zero());
  CHECK(d.p.phase() == Phase::kGoalHold);
  while (d.p.trial_active()) d.step(g, Vec2::Zero());
  CHECK(d.p.phase() == Phase::kReturn);
  d.step(g, Vec2::Zero());  // nothing left to run
  CHECK(d.p.done());
  CHECK(d.p.trial_index() == -1);
}

TEST_CASE("protocol: perturbations off defers perturbed slots and aborts a perturbed trial before onset", "[protocol]") {
  RtConfig cfg;
  cfg.protocol.movements = 3;
  cfg.protocol.perturbed_trials = 3;  // all perturbed
  cfg.protocol.start_hold_s = 0.001;
  Driver d(cfg);
  const Vec2 s = cfg.protocol.start_shoulder_m;
  while (!d.p.trial_active()) d.step(s, Vec2::Zero());
  REQUIRE(d.p.trial_active());
  ProtocolEvents out;
  d.p.set_perturbations_enabled(false, d.k, 0, out);
  REQUIRE(out.n == 1);
  CHECK(out.ev[0].kind == manip::trial_event_t::ABORT);
  CHECK(out.ev[0].reason == AbortReason::kPerturbationsOff);
  for (int i = 0; i < 100; ++i) d.step(s, Vec2::Zero());
  CHECK(d.p.phase() == Phase::kWaiting);  // only perturbed slots remain
  CHECK_FALSE(d.p.trial_active());
  d.p.set_perturbations_enabled(true, d.k, 0, out);
  for (int i = 0; i < 100 && !d.p.trial_active(); ++i) d.step(s, Vec2::Zero());
  CHECK(d.p.trial_active());
}
