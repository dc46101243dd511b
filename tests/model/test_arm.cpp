#include <catch2/catch.hpp>

#include <Eigen/LU>

#include "manip/model/arm.hpp"

using namespace manip;

TEST_CASE("arm: inverse then forward kinematics reproduces the hand, elbow to the right") {
  TwoLinkArm arm{Anthropometrics{}};
  for (double y = 0.30; y <= 0.55; y += 0.05) {
    const Vec2 x(0.0, y);
    const auto q = arm.inverse_kinematics(x);
    REQUIRE(q);
    CHECK((arm.hand_position_m(*q) - x).norm() < 1e-12);
    CHECK((*q)(1) > 0.0);
    CHECK(arm.elbow_position_m(*q).x() > 0.0);
  }
  CHECK_FALSE(arm.inverse_kinematics(Vec2(0.0, 0.7)));
}

TEST_CASE("arm: Jacobian matches finite differences of forward kinematics") {
  TwoLinkArm arm{Anthropometrics{}};
  const Vec2 q(0.4, 1.3);
  const double h = 1e-7;
  Mat2 fd;
  for (int i = 0; i < 2; ++i) {
    Vec2 dq = Vec2::Zero();
    dq(i) = h;
    fd.col(i) = (arm.hand_position_m(q + dq) - arm.hand_position_m(q - dq)) / (2 * h);
  }
  CHECK((fd - arm.jacobian(q)).norm() < 1e-8);
  const Vec2 qd(0.7, -0.3);
  const Mat2 jd_fd = (arm.jacobian(q + h * qd) - arm.jacobian(q - h * qd)) / (2 * h);
  CHECK((jd_fd - arm.jacobian_dot(q, qd)).norm() < 1e-7);
}

TEST_CASE("arm: endpoint inertia is symmetric positive definite with negative off-diagonals (right arm)") {
  TwoLinkArm arm{Anthropometrics{}};
  for (double y : {0.30, 0.40, 0.55}) {
    const auto m = arm.endpoint_inertia_at(Vec2(0.0, y));
    REQUIRE(m);
    CHECK(std::abs((*m)(0, 1) - (*m)(1, 0)) < 1e-12);
    CHECK((*m)(0, 1) < 0.0);
    CHECK(m->determinant() > 0.0);
    CHECK((*m)(0, 0) > 0.0);
  }
}

TEST_CASE("arm: kinetic energy equals the endpoint form 1/2 v^T M_x v") {
  TwoLinkArm arm{Anthropometrics{}};
  const Vec2 q(0.5, 1.6), qd(0.3, -0.8);
  const Vec2 v = arm.jacobian(q) * qd;
  CHECK(arm.kinetic_energy(q, qd) == Approx(0.5 * v.dot(arm.endpoint_inertia(q) * v)).epsilon(1e-12));
}

TEST_CASE("arm: invalid anthropometrics are named") {
  Anthropometrics a;
  a.mass_kg[1] = -1.0;
  const auto why = a.invalid_reason();
  REQUIRE(why);
  CHECK(why->find("forearm.mass_kg") != std::string::npos);
}
