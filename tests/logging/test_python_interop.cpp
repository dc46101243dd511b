// A log written by another lab tool in Python (PyPI lcm + generated types) is read and estimated.
#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>

#include "fixtures.hpp"
#include "manip/estimation/session_estimator.hpp"

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
