// The whole pipeline on simulated sessions with a known answer.
#include <catch2/catch.hpp>

#include "manip/estimation/session_estimator.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"

using namespace manip;
using namespace manip::estimation;

namespace {
Report estimate(const testutil::MemorySession& ms, std::vector<std::string> methods, EstimatorSettings s = {}) {
  s.methods = std::move(methods);
  s.keep_windows = true;
  SessionEstimator est(s);
  for (auto t : ms.trials) est.add_trial(ms.info, std::move(t));
  return est.finish(ms.issues, {});
}
const Summary& session_summary(const Report& r, const std::string& m) {
  for (const auto& s : r.summaries)
    if (s.method == m && s.group.is_session()) return s;
  throw std::runtime_error("no summary for " + m);
}
}  // namespace

TEST_CASE("pipeline: noise-free linear person, pooled methods within 5% (K) and 8% (D) of truth") {
  const auto person = sim::table1_person();
  const auto ms = testutil::simulate_in_memory(testutil::small_design(10), person);
  REQUIRE(ms.trials.size() == 10);
  const auto r = estimate(ms, {"pem", "oe", "paper", "paper-pooled"});
  REQUIRE(r.n_used == 8);
  REQUIRE(r.truth.available);
  CHECK((r.truth.k_npm - person.k_npm).norm() < 1e-9);
  for (const char* m : {"pem", "oe"}) {
    const auto& oe = session_summary(r, m);
    INFO(m << " D = " << oe.d_nspm << "\nK = " << oe.k_npm);
    for (int i = 0; i < 2; ++i)
      for (int j = 0; j < 2; ++j) {
        CHECK(std::abs(oe.k_npm(i, j) - person.k_npm(i, j)) < 0.05 * std::abs(person.k_npm(i, j)));
        CHECK(std::abs(oe.d_nspm(i, j) - person.d_nspm(i, j)) < 0.08 * std::abs(person.d_nspm(i, j)));
      }
  }
  const auto& pem = session_summary(r, "pem");
  REQUIRE(pem.disturbance);
  CHECK(pem.disturbance->box_jenkins);
  // The paper's isolation: Δx tracks the twin difference (§4.3, Fig. 4 reports < 5%).
  int n = 0;
  for (const auto& t : r.trials)
    if (t.method == "paper") {
      ++n;
      CHECK(t.nrmse_dx.maxCoeff() < 0.10);
    }
  CHECK(n == 8);
  // Per-angle summaries exist for all 8 angles.
  for (const char* m : {"pem", "oe"}) {
    int angles = 0;
    for (const auto& s : r.summaries)
      if (s.method == m && s.group.is_angle()) ++angles;
    CHECK(angles == 8);
  }
}

TEST_CASE("pipeline: eq. 21 and the force-sensor route agree on the ideal admittance") {
  const auto ms = testutil::simulate_in_memory(testutil::small_design(9), sim::table1_person());
  const auto r = estimate(ms, {"paper"});
  REQUIRE(!r.windows.empty());
  for (const auto& w : r.windows) {
    // Both routes filter differently (the force route smooths u_pert, inside
    // f_s, with the 30 Hz SG); measured disagreement on the ideal admittance is
    // the floor against which rendering errors are judged (docs/estimator.md).
    double peak = 0, err2 = 0;
    for (std::size_t k = 0; k < w.size(); ++k) {
      peak = std::max(peak, w.u_pert[k].norm());
      err2 += (w.du_ext_adm[k] - w.du_ext_force[k]).squaredNorm();
    }
    const double nrmse = std::sqrt(err2 / static_cast<double>(w.size())) / peak;
    INFO("trial " << w.trial << " NRMSE " << nrmse);
    CHECK(nrmse < 0.05);
  }
}

TEST_CASE("pipeline: automatic cut-off lies above the unperturbed PSD peak") {
  const auto ms = testutil::simulate_in_memory(testutil::small_design(16), sim::table1_person());
  EstimatorSettings s;
  s.cutoff_auto = true;
  const auto r = estimate(ms, {"paper-pooled"}, s);
  REQUIRE(r.psd.n_unperturbed == 8);
  REQUIRE(r.psd.n_perturbed == 8);
  CHECK(r.psd.peak_unperturbed_hz > 0.0);
  CHECK(r.psd.peak_unperturbed_hz < 1.0);
  REQUIRE(std::isfinite(r.psd.cutoff_auto_hz));
  // The search starts at the peak bin itself (session_estimator.cpp), so the
  // cut-off equals the peak when the ratio there already exceeds the threshold.
  CHECK(r.psd.cutoff_auto_hz >= r.psd.peak_unperturbed_hz);
  CHECK(r.cutoff_used_hz == r.psd.cutoff_auto_hz);
}
