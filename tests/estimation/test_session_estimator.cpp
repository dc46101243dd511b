// estimate_log reads on one thread and processes trials on another; the
// result must be exactly that of feeding the same trials to SessionEstimator
// on one thread, for a fixed and for an automatic cut-off, with and without
// the unperturbed signals kept.
#include <catch2/catch.hpp>

#include <string>
#include <vector>

#include "fixtures.hpp"
#include "manip/estimation/session_estimator.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"

using namespace manip;
namespace est = manip::estimation;

namespace {

const std::string& session_log() {
  static const std::string path = [] {
    const auto dir = testutil::temp_dir("session_estimator");
    auto d = testutil::small_design(12);
    const auto rec = testutil::record(d, sim::table1_person());
    testutil::write_recorded(rec, dir + "/session.lcm");
    return dir + "/session.lcm";
  }();
  return path;
}

est::Report sequential(const std::string& path, const est::EstimatorSettings& s, bool keep_unperturbed) {
  est::SessionEstimator e(s);
  est::TrialAssembler asmb([&](const est::SessionInfo& info, est::TrialData&& t) { e.add_trial(info, std::move(t)); });
  asmb.set_keep_unperturbed_signals(keep_unperturbed);
  logging::read_log(path, asmb);
  asmb.finish();
  return e.finish(asmb.issues(), asmb.warnings());
}

void require_same(const est::Report& a, const est::Report& b) {
  REQUIRE(a.n_trials == b.n_trials);
  REQUIRE(a.n_perturbed == b.n_perturbed);
  REQUIRE(a.n_used == b.n_used);
  CHECK(a.cutoff_used_hz == b.cutoff_used_hz);
  CHECK(a.psd.p_unperturbed == b.psd.p_unperturbed);  // bit for bit
  CHECK(a.psd.p_perturbed == b.psd.p_perturbed);
  CHECK(a.psd.n_unperturbed == b.psd.n_unperturbed);
  CHECK(a.psd.n_perturbed == b.psd.n_perturbed);
  REQUIRE(a.trials.size() == b.trials.size());
  for (std::size_t i = 0; i < a.trials.size(); ++i) {
    CHECK(a.trials[i].trial == b.trials[i].trial);
    CHECK(a.trials[i].est.d_nspm == b.trials[i].est.d_nspm);
    CHECK(a.trials[i].est.k_npm == b.trials[i].est.k_npm);
  }
  REQUIRE(a.summaries.size() == b.summaries.size());
  for (std::size_t i = 0; i < a.summaries.size(); ++i) {
    CHECK(a.summaries[i].group == b.summaries[i].group);
    CHECK(a.summaries[i].d_nspm == b.summaries[i].d_nspm);
    CHECK(a.summaries[i].k_npm == b.summaries[i].k_npm);
  }
  REQUIRE(a.issues.size() == b.issues.size());
  for (std::size_t i = 0; i < a.issues.size(); ++i) CHECK(a.issues[i].reason == b.issues[i].reason);
}

}  // namespace

TEST_CASE("session estimator: the pipelined estimate_log equals a sequential run, bit for bit") {
  for (const bool automatic : {false, true}) {
    est::EstimatorSettings s;
    s.methods = {"paper", "paper-pooled"};
    s.cutoff_auto = automatic;
    s.psd_nfft = 16384;
    INFO("cutoff_auto " << automatic);
    const auto piped = est::estimate_log(session_log(), s);
    REQUIRE(piped.n_used > 0);
    require_same(piped, sequential(session_log(), s, true));
    require_same(piped, sequential(session_log(), s, false));
  }
}

TEST_CASE("session estimator: estimate_log is deterministic across runs") {
  est::EstimatorSettings s;
  s.methods = {"paper"};
  s.psd_nfft = 16384;
  const auto a = est::estimate_log(session_log(), s);
  for (int i = 0; i < 3; ++i) require_same(a, est::estimate_log(session_log(), s));
}

TEST_CASE("session estimator: unperturbed trials can be read with x only") {
  std::vector<est::TrialData> full, lean;
  for (const bool keep : {true, false}) {
    est::TrialAssembler asmb([&](const est::SessionInfo&, est::TrialData&& t) { (keep ? full : lean).push_back(std::move(t)); });
    asmb.set_keep_unperturbed_signals(keep);
    logging::read_log(session_log(), asmb);
    asmb.finish();
  }
  REQUIRE(full.size() == lean.size());
  for (std::size_t i = 0; i < full.size(); ++i) {
    CHECK(full[i].x_m == lean[i].x_m);
    if (full[i].perturbed) {
      CHECK(full[i].f_sensor_n == lean[i].f_sensor_n);
      CHECK(full[i].x_twin_m == lean[i].x_twin_m);
    } else {
      CHECK(lean[i].f_sensor_n.empty());
      CHECK(full[i].f_sensor_n.size() == full[i].x_m.size());
    }
  }
}
