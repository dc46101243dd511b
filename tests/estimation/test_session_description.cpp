// The estimator reads every session constant from the session message
// (schema::SessionDescription): a changed value is used, an invalid one is
// refused naming the file and the field.
#include <catch2/catch.hpp>

#include <cmath>

#include "fixtures.hpp"
#include "manip/common/errors.hpp"
#include "manip/estimation/session_estimator.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"

using namespace manip;
using namespace manip::estimation;

namespace {

Report estimate(const std::string& path, bool estimate_m) {
  EstimatorSettings s;
  s.methods = {"paper-pooled", "oe"};
  s.ls.estimate_m = estimate_m;
  return estimate_log(path, s);
}

const Summary& session(const Report& r, const std::string& m) {
  for (const auto& s : r.summaries)
    if (s.method == m && s.group.is_session()) return s;
  throw std::runtime_error("no session summary for " + m);
}

}  // namespace

TEST_CASE("session message: a changed handle mass is used by the estimator as eq. 21 says") {
  const auto dir = testutil::temp_dir("session_description");
  auto rec = testutil::record(testutil::small_design(10), sim::table1_person());
  // The rig's handle (schema default) in one log, 0.30 kg more in the other;
  // the simulated motion is the same in both.
  rec.session.m_handle_kg[0] = rec.session.m_handle_kg[1] = 0.25;
  testutil::write_recorded(rec, dir + "/a.lcm");
  const double dm = 0.30;
  rec.session.m_handle_kg[0] = rec.session.m_handle_kg[1] = 0.25 + dm;
  testutil::write_recorded(rec, dir + "/b.lcm");

  const auto a = estimate(dir + "/a.lcm", true);
  const auto b = estimate(dir + "/b.lcm", true);
  CHECK(a.info.m_handle_shoulder_kg().isApprox(Mat2::Identity() * 0.25));
  CHECK(b.info.m_handle_shoulder_kg().isApprox(Mat2::Identity() * 0.55));

  // Eq. 21: Δu_ext = u_pert − (M_adm + M_handle) Δẍ − D_adm Δẋ. A handle
  // heavier by δ removes δ·Δẍ from Δu_ext; with M estimated (eq. 24-29) that is
  // exactly M → M − δ I in the least-squares solution, D and K unchanged.
  const auto& pa = session(a, "paper-pooled");
  const auto& pb = session(b, "paper-pooled");
  INFO("M a = " << pa.m_kg << "\nM b = " << pb.m_kg);
  CHECK((pb.m_kg - (pa.m_kg - dm * Mat2::Identity())).cwiseAbs().maxCoeff() < 1e-6);
  CHECK((pb.d_nspm - pa.d_nspm).cwiseAbs().maxCoeff() < 1e-6 * pa.d_nspm.norm());
  CHECK((pb.k_npm - pa.k_npm).cwiseAbs().maxCoeff() < 1e-6 * pa.k_npm.norm());

  // The output-error model carries the same inertia, M_BSP + M_adm + M_handle:
  // the same motion fitted with 0.30 kg more inertia must give other D, K.
  const auto& oa = session(a, "oe");
  const auto& ob = session(b, "oe");
  CHECK((ob.k_npm - oa.k_npm).norm() > 1e-3 * oa.k_npm.norm());
}

TEST_CASE("session message: an invalid value refuses the log, naming the file and the field (exit code 4)") {
  const auto dir = testutil::temp_dir("session_description_invalid");
  auto rec = testutil::record(testutil::small_design(10), sim::table1_person());
  rec.session.m_adm_kg[1] = std::nan("");
  testutil::write_recorded(rec, dir + "/bad.lcm");
  try {
    (void)estimate(dir + "/bad.lcm", false);
    FAIL("an invalid session message was accepted");
  } catch (const manip::Error& e) {
    CHECK(e.exit_code() == manip::exit_code::kInput);
    const std::string what = e.what();
    CHECK(what.find(dir + "/bad.lcm") == 0);
    CHECK(what.find("m_adm_kg[1]") != std::string::npos);
  }
}
