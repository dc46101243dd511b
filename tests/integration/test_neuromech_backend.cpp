// manip_rt's sim backend with the neuromechanical arm as the simulated person
// (simulation issue: the same model runs inside the 4 kHz loop).
#include <catch2/catch.hpp>

#include <unistd.h>

#include <filesystem>
#include <sstream>

#include "manip/runtime/config.hpp"
#include "manip/estimation/session_estimator.hpp"
#include "manip/common/errors.hpp"
#include "manip/runtime/backends.hpp"
#include "manip/runtime/session.hpp"
#include "../hardware/offline_run.hpp"
#include "../hardware/sanitized.hpp"

using manip::runtime::load_rt_config;

namespace {
std::string src(const std::string& rel) { return std::string(MANIP_SOURCE_DIR) + "/" + rel; }
}  // namespace

TEST_CASE("sim backend: the neuromechanical arm runs a session inside the loop and the log estimates", "[session]") {
  const auto base = load_rt_config(src("config/rt.yaml"));
  auto ov = manip::runtime::trials_overrides(base, kSanitized ? 1 : 8);
  ov.push_back({"sim.human.model", "neuromech"});
  ov.push_back({"sim.human.arm_config", src("config/arm_model.yaml")});
  const auto cfg = load_rt_config(src("config/rt.yaml"), ov);
  const auto backend = manip::runtime::make_backend("sim", cfg);
  REQUIRE(backend);
  const auto path = (std::filesystem::temp_directory_path() / ("manip_rt_neuromech_" + std::to_string(::getpid()) + ".lcm")).string();
  const auto opt = offline_run_options(path);
  std::ostringstream out;
  const auto rep = manip::runtime::run_session(cfg, *backend, opt, out);
  INFO(out.str() << rep.summary());
  REQUIRE(rep.exit_code == manip::exit_code::kOk);
  CHECK(rep.trials.perturbed_completed == cfg.perturbed_count());
  manip::estimation::EstimatorSettings s;
  s.methods = {"paper-pooled"};
  const auto r = manip::estimation::estimate_log(path, s);
  CHECK(r.n_used == cfg.perturbed_count());
  std::filesystem::remove(path);
}

TEST_CASE("sim backend: a bad neuromech parameter file is a configuration error naming the file", "[session]") {
  const auto base = load_rt_config(src("config/rt.yaml"));
  const auto cfg = load_rt_config(src("config/rt.yaml"), {{"sim.human.model", "neuromech"},
                                                          {"sim.human.arm_config", "/nonexistent/arm.yaml"}});
  try {
    (void)manip::runtime::make_backend("sim", cfg);
    FAIL("a missing arm_config was accepted");
  } catch (const manip::Error& e) {
    CHECK(e.exit_code() == manip::exit_code::kConfig);
    CHECK(std::string(e.what()).find("/nonexistent/arm.yaml") != std::string::npos);
  }
  (void)base;
}
