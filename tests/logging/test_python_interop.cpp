// A log written by another lab tool in Python (PyPI lcm + generated types) is read and estimated.
#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>

#include "fixtures.hpp"
#include "manip/estimation/session_estimator.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/schema/codes.hpp"

using namespace manip;

TEST_CASE("python interop: a log written by Python's lcm package is read and estimated", "[python]") {
  const std::string py = MANIP_PYTHON;
  REQUIRE(std::filesystem::exists(py));  // scripts/setup.sh creates .venv with pinned PyPI lcm
  const auto dir = testutil::temp_dir("pylog");
  const std::string cmd = py + " " + testutil::fixture_path("logging/write_python_log.py") + " " + MANIP_BINARY_DIR +
                          "/python " + dir + "/py.lcm";
  REQUIRE(std::system(cmd.c_str()) == 0);
  estimation::EstimatorSettings s;
  s.methods = {"oe", "paper"};
  const auto r = estimation::estimate_log(dir + "/py.lcm", s);
  CHECK(r.info.source == "python");
  CHECK(r.n_trials == 8);
  CHECK(r.n_used == 8);
  const Mat2 k_true = (Mat2() << 110.52, -106.05, -106.05, 313.75).finished();
  const Mat2 d_true = (Mat2() << 10.98, -7.94, -8.54, 6.75).finished();
  for (const auto& sm : r.summaries)
    if (sm.method == "oe" && sm.group.is_session()) {
      INFO("D = " << sm.d_nspm << "\nK = " << sm.k_npm);
      CHECK((sm.k_npm - k_true).norm() < 0.1 * k_true.norm());
      CHECK((sm.d_nspm - d_true).norm() < 0.15 * d_true.norm());
    }
}

TEST_CASE("python interop: the README example classifies states by the schema's named constants", "[python]") {
  // Python writes a log with codes taken from the generated constants; the C++
  // reader's counts per phase (schema::Phase) must equal Python's counts per
  // PHASE_* name, and every in-trial state must be REACH or PERTURBATION.
  const std::string py = MANIP_PYTHON;
  REQUIRE(std::filesystem::exists(py));
  const auto dir = testutil::temp_dir("pyconst");
  const std::string log = dir + "/py.lcm";
  REQUIRE(std::system((py + " " + testutil::fixture_path("logging/write_python_log.py") + " " + MANIP_BINARY_DIR +
                       "/python " + log).c_str()) == 0);
  const std::string out = dir + "/counts.txt";
  REQUIRE(std::system((py + " " + testutil::fixture_path("logging/count_phases.py") + " " + MANIP_BINARY_DIR +
                       "/python " + log + " > " + out).c_str()) == 0);
  std::map<std::string, long> py_counts;
  {
    std::ifstream f(out);
    std::string name;
    long n = 0;
    while (f >> name >> n) py_counts[name] = n;
  }
  struct Counter : logging::SessionHandler {
    std::map<std::string, long> by_phase;
    long running = 0;
    void on_state(const manip::state_t& s) override {
      by_phase[std::string("PHASE_") + schema::phase_name(static_cast<schema::Phase>(s.phase))]++;
      running += s.mode == static_cast<std::int8_t>(schema::Mode::kRunning);
    }
  } c;
  logging::read_log(log, c);
  CHECK(py_counts.at("MODE_RUNNING") == c.running);
  CHECK(c.running > 0);
  CHECK(c.by_phase["PHASE_PERTURBATION"] > 0);
  CHECK(c.by_phase["PHASE_REACH"] > 0);
  for (const auto& [name, n] : c.by_phase) CHECK(py_counts.at(name) == n);
}
