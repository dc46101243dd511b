// A method added from outside the library (this file and one registration
// line, as docs/estimator.md shows) is listed by the registry, accepted by
// the settings, run by SessionEstimator and written by every report.
#include <catch2/catch.hpp>

#include <fstream>

#include "fixtures.hpp"
#include "manip/estimation/equation_error.hpp"
#include "manip/estimation/methods/registry.hpp"
#include "manip/estimation/report.hpp"
#include "manip/estimation/session_estimator.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"

using namespace manip;
using namespace manip::estimation;

namespace {

// Toy: the paper's pooled least squares on every second requested trial.
class EveryOtherTrial final : public Method {
 public:
  std::string name() const override { return "toy-every-other"; }
  std::string description() const override { return "test only: pooled equation error on every second trial"; }
  bool per_trial() const override { return false; }
  DataWindow windows() const override { return DataWindow::variational; }
  ImpedanceEstimate fit(const SessionWindows& d, const FitRequest& r) const override {
    std::vector<VariationalWindow> w;
    std::vector<Mat2> m;
    for (std::size_t k = 0; k < r.trials.size(); k += 2) {
      w.push_back(d.variational[r.trials[k]]);
      m.push_back(d.m_bsp[r.trials[k]]);
    }
    return fit_equation_error(w, m, d.settings->ls);
  }
};
const MethodRegistration kToy(std::make_unique<EveryOtherTrial>());

}  // namespace

TEST_CASE("registry: the built-in methods in their documented order, pem the default") {
  const auto all = all_methods();
  REQUIRE(all.size() >= 5);
  CHECK(std::vector<std::string>(all.begin(), all.begin() + 5) ==
        std::vector<std::string>{"pem", "paper", "paper-pooled", "oe", "oe-trial"});
  CHECK(default_method() == "pem");
  CHECK(find_method("paper")->per_trial());
  CHECK(find_method("oe-trial")->per_trial());
  CHECK_FALSE(find_method("pem")->per_trial());
  CHECK_FALSE(find_method("paper-pooled")->per_trial());
  CHECK_FALSE(find_method("oe")->per_trial());
  CHECK(find_method("nope") == nullptr);
  CHECK_THROWS_AS(register_method(std::make_unique<EveryOtherTrial>()), std::invalid_argument);  // name taken
}

TEST_CASE("registry: a method registered from a test file runs through SessionEstimator into the reports") {
  const auto all = all_methods();
  REQUIRE(std::find(all.begin(), all.end(), "toy-every-other") != all.end());

  // The settings file accepts it by name.
  const auto dir = testutil::temp_dir("method_registry");
  std::ofstream(dir + "/s.yaml") << "methods: [toy-every-other, paper-pooled]\n";
  EstimatorSettings s = load_estimator_settings(dir + "/s.yaml");
  REQUIRE(s.methods == std::vector<std::string>{"toy-every-other", "paper-pooled"});
  s.keep_windows = true;

  const auto ms = testutil::simulate_in_memory(testutil::small_design(10), sim::table1_person());
  SessionEstimator est(s);
  for (auto t : ms.trials) est.add_trial(ms.info, std::move(t));
  const auto r = est.finish(ms.issues, {});
  REQUIRE(r.n_used == 8);
  REQUIRE(r.windows.size() == 8);

  const Summary* toy = nullptr;
  int toy_angles = 0;
  for (const auto& sm : r.summaries)
    if (sm.method == "toy-every-other") {
      if (sm.group.is_session()) toy = &sm;
      else ++toy_angles;
    }
  REQUIRE(toy != nullptr);
  CHECK(toy_angles == 8);  // one per angle (one trial each)
  CHECK(toy->pooled);

  // Independent route: the same fit called directly on trials 0, 2, 4, 6.
  std::vector<VariationalWindow> w;
  std::vector<Mat2> m;
  const TwoLinkArm arm(ms.info.anthropometrics);
  for (std::size_t k = 0; k < r.windows.size(); k += 2) {
    w.push_back(r.windows[k]);
    const auto& t = *std::find_if(ms.trials.begin(), ms.trials.end(), [&](const TrialData& x) { return x.trial == r.windows[k].trial; });
    m.push_back(*arm.endpoint_inertia_at(t.x_m[static_cast<std::size_t>(t.onset_index)]));
  }
  const auto direct = fit_equation_error(w, m, s.ls);
  CHECK(toy->d_nspm.isApprox(direct.d_nspm, 1e-12));
  CHECK(toy->k_npm.isApprox(direct.k_npm, 1e-12));
  CHECK(direct.n_trials == 4);

  // It lands in the JSON, the text and the CSV.
  const auto j = to_json(r, "mem");
  CHECK(j["session_summary"].contains("toy-every-other"));
  CHECK(j["settings"]["methods"][0] == "toy-every-other");
  CHECK(format_text(r, "mem").find("toy-every-other: pooled fit") != std::string::npos);
  write_csv({{"mem", r}}, dir + "/out.csv", true);
  std::ifstream csv(dir + "/out.csv");
  const std::string text((std::istreambuf_iterator<char>(csv)), std::istreambuf_iterator<char>());
  CHECK(text.find(",toy-every-other,false,false,session,,,D11,damping,N s/m,") != std::string::npos);
}

TEST_CASE("summary groups are typed: the session, then each angle with its numeric angle in JSON and CSV") {
  const auto ms = testutil::simulate_in_memory(testutil::small_design(10), sim::table1_person());
  EstimatorSettings s;
  s.methods = {"paper-pooled"};
  SessionEstimator est(s);
  for (auto t : ms.trials) est.add_trial(ms.info, std::move(t));
  const auto r = est.finish(ms.issues, {});
  REQUIRE(r.summaries.size() == 9);
  CHECK(r.summaries[0].group.is_session());
  CHECK(r.summaries[0].group.label() == "session");
  std::vector<double> angles;
  for (std::size_t i = 1; i < r.summaries.size(); ++i) {
    REQUIRE(r.summaries[i].group.is_angle());
    angles.push_back(r.summaries[i].group.angle_deg);
  }
  // Independent reference: the perturbed trials' own angles, one per angle in small_design.
  std::vector<double> trial_angles;
  for (const auto& t : ms.trials)
    if (t.perturbed) {
      double d = std::fmod(t.angle_rad * 180.0 / M_PI, 360.0);
      trial_angles.push_back(std::round((d < 0 ? d + 360.0 : d) * 1000.0) / 1000.0);
    }
  std::sort(trial_angles.begin(), trial_angles.end());
  CHECK(angles == trial_angles);
  const auto j = to_json(r, "mem");
  CHECK(j["summaries"][0]["angle_deg"].is_null());
  CHECK(j["summaries"][1]["angle_deg"].get<double>() == Approx(angles[0]));
  CHECK(j["summaries"][1]["group"] == r.summaries[1].group.label());
}
