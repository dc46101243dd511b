// TrialAssembler groups trials by the `cycle` each message carries, not by
// arrival order: logs from other writers (START just after the trial's first
// state, END just before its last, ONSET after its state) must give exactly
// the trials of the canonical order. Expected trial extents come from the
// recorded START/END events themselves (START cycle .. END cycle inclusive).
#include <catch2/catch.hpp>

#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "fixtures.hpp"
#include "manip/estimation/session_estimator.hpp"
#include "manip/estimation/trial_data.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"

using namespace manip;
namespace est = manip::estimation;
using Item = testutil::Recorded::Item;

namespace {

const testutil::Recorded& recorded() {
  static const testutil::Recorded rec = [] {
    auto d = testutil::small_design(9);
    d.write_twins = false;
    return testutil::record(d, sim::table1_person());
  }();
  return rec;
}

bool is_event(const Item& it, int kind) { return it.kind == 1 && it.event.kind == kind; }

// The same messages in another writer's order: each START after `start_late`
// further states, each ONSET after `onset_late` further states, each END
// before the trial's last `end_early` states.
testutil::Recorded reorder(const testutil::Recorded& in, int start_late, int onset_late, int end_early) {
  testutil::Recorded out;
  out.session = in.session;
  struct Delayed {
    Item item;
    int states_left;
  };
  std::vector<Delayed> delayed;
  for (const auto& it : in.items) {
    if ((is_event(it, manip::trial_event_t::START) && start_late > 0) ||
        (is_event(it, manip::trial_event_t::ONSET) && onset_late > 0)) {
      delayed.push_back({it, is_event(it, manip::trial_event_t::START) ? start_late : onset_late});
      continue;
    }
    if (is_event(it, manip::trial_event_t::END) && end_early > 0) {
      auto pos = out.items.end();
      for (int n = 0; n < end_early;) {
        REQUIRE(pos != out.items.begin());
        --pos;
        if (pos->kind == 0) ++n;
      }
      out.items.insert(pos, it);
      continue;
    }
    out.items.push_back(it);
    if (it.kind == 0) {
      for (auto& d : delayed) --d.states_left;
      for (auto d = delayed.begin(); d != delayed.end();) {
        if (d->states_left == 0) {
          out.items.push_back(d->item);
          d = delayed.erase(d);
        } else {
          ++d;
        }
      }
    }
  }
  REQUIRE(delayed.empty());
  REQUIRE(out.items.size() == in.items.size());
  return out;
}

struct Assembled {
  std::vector<est::TrialData> trials;
  std::vector<est::TrialIssue> issues;
};

Assembled assemble(const testutil::Recorded& rec, const std::string& name, std::int64_t tolerance = -1) {
  const auto dir = testutil::temp_dir("trial_assembly");
  const std::string path = dir + "/" + name + ".lcm";
  testutil::write_recorded(rec, path);
  Assembled a;
  est::TrialAssembler asmb([&](const est::SessionInfo&, est::TrialData&& t) { a.trials.push_back(std::move(t)); });
  if (tolerance >= 0) asmb.set_reorder_tolerance_cycles(tolerance);
  logging::read_log(path, asmb);
  asmb.finish();
  a.issues = asmb.issues();
  return a;
}

// START cycle, END cycle, ONSET cycle (-1) per trial, from the recorded events.
struct Extent {
  std::int64_t start{-1}, end{-1}, onset{-1};
};
std::map<int, Extent> extents(const testutil::Recorded& rec) {
  std::map<int, Extent> m;
  for (const auto& it : rec.items) {
    if (it.kind != 1) continue;
    auto& e = m[it.event.trial];
    if (it.event.kind == manip::trial_event_t::START) e.start = it.event.cycle;
    if (it.event.kind == manip::trial_event_t::END) e.end = it.event.cycle;
    if (it.event.kind == manip::trial_event_t::ONSET) e.onset = it.event.cycle;
  }
  return m;
}

void require_trials_match_events(const Assembled& a, const testutil::Recorded& rec) {
  const auto ext = extents(rec);
  REQUIRE(a.issues.empty());
  REQUIRE(a.trials.size() == ext.size());
  for (const auto& t : a.trials) {
    CAPTURE(t.trial);
    const auto& e = ext.at(t.trial);
    CHECK(t.start_cycle == e.start);
    CHECK(static_cast<std::int64_t>(t.size()) == e.end - e.start + 1);
    CHECK(t.onset_index == (e.onset >= 0 ? e.onset - e.start : -1));
    CHECK(t.perturbed == (e.onset >= 0));
  }
}

}  // namespace

TEST_CASE("trial assembly: canonical order gives every trial from its START cycle to its END cycle") {
  require_trials_match_events(assemble(recorded(), "canonical"), recorded());
}

TEST_CASE("trial assembly: START just after the first state (third-party writer) loses no trial") {
  const auto a = assemble(reorder(recorded(), 1, 0, 0), "start_late");
  require_trials_match_events(a, recorded());
  // Bit for bit the samples of the canonical order.
  const auto c = assemble(recorded(), "canonical2");
  REQUIRE(a.trials.size() == c.trials.size());
  for (std::size_t i = 0; i < a.trials.size(); ++i) {
    CHECK(a.trials[i].x_m == c.trials[i].x_m);
    CHECK(a.trials[i].f_sensor_n == c.trials[i].f_sensor_n);
  }
}

TEST_CASE("trial assembly: END before the last state (the controller's order) and late ONSET keep every sample") {
  require_trials_match_events(assemble(reorder(recorded(), 0, 3, 1), "end_early"), recorded());
  require_trials_match_events(assemble(reorder(recorded(), 7, 20, 5), "mixed"), recorded());
}

TEST_CASE("trial assembly: events later than the reorder tolerance are reported, not silently mis-assembled") {
  // Within the tolerance (10 cycles): fine.
  require_trials_match_events(assemble(reorder(recorded(), 10, 0, 0), "tol_ok", 10), recorded());
  // Beyond it: every trial is reported with the reason, none handed over
  // with its first samples missing.
  const auto a = assemble(reorder(recorded(), 25, 0, 0), "tol_exceeded", 10);
  CHECK(a.trials.empty());
  REQUIRE(a.issues.size() == extents(recorded()).size());
  for (const auto& i : a.issues) CHECK_THAT(i.reason, Catch::Contains("more than the reorder tolerance of 10 cycles"));
}

TEST_CASE("trial assembly: estimate_log on a START-after-first-state log uses every perturbed trial") {
  const auto dir = testutil::temp_dir("trial_assembly_est");
  testutil::write_recorded(reorder(recorded(), 1, 0, 0), dir + "/third_party.lcm");
  est::EstimatorSettings s;
  s.methods = {"paper"};
  const auto r = est::estimate_log(dir + "/third_party.lcm", s);
  CHECK(r.n_trials == 9);
  CHECK(r.n_perturbed == 8);
  CHECK(r.n_used == 8);
  CHECK(r.issues.empty());
}

// The admittance reference as the position (trial_data.hpp): manip_rt logs
// the PD's set-point for the next sample, manip_sim the simulated handle at
// t_k; aligned by the producer's convention, refused naming the trial when
// the log has no finite reference.
TEST_CASE("trial data: the admittance reference is aligned by its producer's convention, or refused naming the trial") {
  using manip::Vec2;
  CHECK(manip::estimation::reference_shift_for("manip_rt/sim") == 1);
  CHECK(manip::estimation::reference_shift_for("manip_rt/can") == 1);
  CHECK(manip::estimation::reference_shift_for("manip_sim/linear") == 0);
  CHECK(manip::estimation::reference_shift_for("manip_sim/neuromech") == 0);
  manip::estimation::TrialData t;
  t.trial = 7;
  const std::size_t n = 400;
  const double dt = 2.5e-4;
  auto path = [&](double time_s) { return Vec2(0.01 * std::sin(3.0 * time_s), 0.4 + 0.02 * time_s * time_s); };
  for (std::size_t k = 0; k < n; ++k) {
    const double ts = static_cast<double>(k) * dt;
    t.x_m.push_back(path(ts));
    t.x_ref_m.push_back(path(ts + dt));  // the set-point for the next sample
  }
  auto a = manip::estimation::aligned_reference(t, 1);
  REQUIRE(a.size() == n);
  for (std::size_t k = 1; k < n; ++k) CHECK(a[k] == t.x_ref_m[k - 1]);
  CHECK((a[0] - path(0.0)).norm() < 1e-8);  // extrapolated linearly to the first sample (the path's curvature: 2.5 nm)
  CHECK(manip::estimation::aligned_reference(t, 0) == t.x_ref_m);
  // Imported logs carry no reference (NaN), or none at all.
  t.x_ref_m[5].x() = std::numeric_limits<double>::quiet_NaN();
  try {
    (void)manip::estimation::aligned_reference(t, 1);
    FAIL("a NaN reference was accepted");
  } catch (const std::invalid_argument& e) {
    CHECK(std::string(e.what()).find("trial 7: ") == 0);
    CHECK(std::string(e.what()).find("x_ref") != std::string::npos);
  }
  t.x_ref_m.clear();
  CHECK_THROWS_AS(manip::estimation::aligned_reference(t, 0), std::invalid_argument);
}

// position_source auto (the default): the reference on a controller's log,
// the encoder on a manip_sim log; under auto a trial without a finite
// reference keeps the encoder and is listed, under an explicit "reference" it
// is excluded, naming it. The recorded log is manip_sim's (its x_ref is the
// simulated handle); relabelled as manip_rt's, its x_ref reads as the
// set-point for the next sample and is shifted by one.
TEST_CASE("position auto: the reference on a manip_rt log, the encoder elsewhere, a trial without a reference kept on the encoder") {
  CHECK(est::resolved_position(est::PositionSource::automatic, "manip_rt/sim") == est::PositionSource::reference);
  CHECK(est::resolved_position(est::PositionSource::automatic, "manip_rt/can") == est::PositionSource::reference);
  CHECK(est::resolved_position(est::PositionSource::automatic, "manip_sim/linear") == est::PositionSource::encoder);
  CHECK(est::resolved_position(est::PositionSource::automatic, "manip_import:rig.mat") == est::PositionSource::encoder);
  CHECK(est::resolved_position(est::PositionSource::automatic, "") == est::PositionSource::encoder);
  CHECK(est::resolved_position(est::PositionSource::encoder, "manip_rt/sim") == est::PositionSource::encoder);
  CHECK(est::resolved_position(est::PositionSource::reference, "manip_sim") == est::PositionSource::reference);
  CHECK(est::resolved_position(est::PositionSource::tracked, "manip_sim") == est::PositionSource::tracked);
  for (const auto p : {est::PositionSource::encoder, est::PositionSource::reference, est::PositionSource::automatic,
                       est::PositionSource::tracked})
    CHECK(est::parse_position_source(est::to_string(p)) == p);
  CHECK(!est::parse_position_source("stage"));

  // The first perturbed trial loses its reference (NaN, as an imported log's).
  testutil::Recorded rec = recorded();
  rec.session.source = "manip_rt/sim";
  int damaged = -1;
  for (const auto& it : rec.items)
    if (is_event(it, manip::trial_event_t::ONSET)) {
      damaged = it.event.trial;
      break;
    }
  REQUIRE(damaged >= 0);
  for (auto& it : rec.items)
    if (it.kind == 0 && it.state.trial == damaged) it.state.x_ref_workspace_m[0] = std::numeric_limits<double>::quiet_NaN();
  const auto dir = testutil::temp_dir("position_auto");
  testutil::write_recorded(rec, dir + "/rt_labelled.lcm");
  est::EstimatorSettings s;
  s.methods = {"paper"};
  REQUIRE(s.position == est::PositionSource::automatic);
  const auto a = est::estimate_log(dir + "/rt_labelled.lcm", s);
  CHECK(a.position_used == est::PositionSource::reference);
  CHECK(a.n_used == 8);
  CHECK(a.n_reference_shift1 == 7);
  CHECK(a.n_reference_shift0 == 0);
  CHECK(a.reference_fallback_trials == std::vector<int>{damaged});
  CHECK(a.issues.empty());
  s.position = est::PositionSource::reference;
  const auto r = est::estimate_log(dir + "/rt_labelled.lcm", s);
  CHECK(r.n_used == 7);
  CHECK(r.reference_fallback_trials.empty());
  REQUIRE(r.issues.size() == 1);
  CHECK(r.issues[0].trial == damaged);
  CHECK_THAT(r.issues[0].reason, Catch::Contains("x_ref"));
  s.position = est::PositionSource::tracked;  // needs the reference too: excluded the same way
  const auto tk = est::estimate_log(dir + "/rt_labelled.lcm", s);
  CHECK(tk.position_used == est::PositionSource::tracked);
  CHECK(tk.n_used == 7);
  CHECK(tk.n_reference_shift1 == 7);
  REQUIRE(tk.issues.size() == 1);
  CHECK(tk.issues[0].trial == damaged);
  // The same log as manip_sim wrote it: auto takes the encoder.
  s.position = est::PositionSource::automatic;
  testutil::write_recorded(recorded(), dir + "/sim.lcm");
  const auto e = est::estimate_log(dir + "/sim.lcm", s);
  CHECK(e.position_used == est::PositionSource::encoder);
  CHECK(e.n_reference_shift0 + e.n_reference_shift1 == 0);
  s.position = est::PositionSource::encoder;
  const auto e2 = est::estimate_log(dir + "/sim.lcm", s);
  REQUIRE(!e.summaries.empty());
  REQUIRE(!e2.summaries.empty());
  CHECK(e.summaries[0].d_nspm == e2.summaries[0].d_nspm);
}
