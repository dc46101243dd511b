// The human-model factory: one registry keyed by name. This file is also the
// proof that adding a model takes one new file and one registration line: the
// toy model below is registered by the single `registered` line and then runs
// a whole session through manip_sim's path (make_human + run_session).
#include <catch2/catch.hpp>

#include <cmath>
#include <stdexcept>

#include "manip/common/errors.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/sim/human_factory.hpp"
#include "manip/sim/min_jerk.hpp"
#include "manip/sim/presets.hpp"
#include "manip/sim/session_runner.hpp"

using namespace manip;
using namespace manip::sim;

namespace {

// A toy person: the hand is a point mass that follows the minimum-jerk plan
// with a stiff spring and a damper (no noise, no delay).
class SpringPerson final : public HumanModel {
 public:
  void begin_trial(const ReachSpec& r, std::uint64_t) override {
    r_ = r;
    t_ = 0.0;
    x_ = r.start_shoulder_m;
    xd_.setZero();
  }
  void endpoint_dynamics(Mat2& m, Vec2& h) override {
    const auto plan = min_jerk(r_.start_shoulder_m, r_.goal_shoulder_m, r_.t_start_s, r_.duration_s, 0.0, t_);
    m = Mat2::Identity() * 1.5;
    // Feed-forward for the expected load (5.25 kg, 15 Ns/m) plus the spring and damper.
    h = (m + Mat2::Identity() * 5.25) * plan.xdd + 15.0 * plan.xd + 800.0 * (plan.x - x_) + 60.0 * (plan.xd - xd_);
  }
  void advance(double dt, const Vec2& xdd) override {
    xd_ += xdd * dt;
    x_ += xd_ * dt;
    t_ += dt;
  }
  Vec2 hand_position_m() const override { return x_; }
  Vec2 hand_velocity_mps() const override { return xd_; }
  double time_s() const override { return t_; }

 private:
  ReachSpec r_;
  double t_{0};
  Vec2 x_{Vec2::Zero()}, xd_{Vec2::Zero()};
};

BuiltHuman build_spring_person(const HumanSpec& s) {
  BuiltHuman b;
  b.model = std::make_unique<SpringPerson>();
  b.step_s = s.plant_step_s > 0.0 ? s.plant_step_s : 1.0 / (4.0 * s.sample_rate_hz);
  return b;
}

const bool registered = register_human_model({"toy-spring", "test: spring-damper point mass", &build_spring_person});

struct Count final : logging::SessionHandler {
  int states{0}, onsets{0};
  std::string source;
  void on_session(const manip::session_t& m) override { source = m.source; }
  void on_state(const manip::state_t&) override { ++states; }
  void on_trial_event(const manip::trial_event_t& e) override { onsets += e.kind == manip::trial_event_t::ONSET; }
};

}  // namespace

TEST_CASE("sim factory: a model registered by one line runs a whole session") {
  REQUIRE(registered);
  bool listed = false;
  for (const auto& m : human_models()) listed = listed || m.name == "toy-spring";
  CHECK(listed);
  HumanSpec spec;
  spec.model = "toy-spring";
  auto built = make_human(spec);
  REQUIRE(built.model);
  CHECK(built.step_s == Approx(1.0 / 16000.0));
  SessionDesign d;
  d.n_movements = 10;
  d.reps_per_angle = 1;
  d.substeps = 4;
  d.session.source = "manip_sim/toy-spring";
  Count c;
  const auto sum = run_session(d, *built.model, c);
  CHECK(sum.trials == 10);
  CHECK(c.onsets == 8);  // the toy reaches through the trigger line on every perturbed trial
  CHECK(c.source == "manip_sim/toy-spring");
  CHECK(c.states == sum.cycles);
  CHECK_THROWS_AS(register_human_model({"toy-spring", "again", &build_spring_person}), std::logic_error);
  CHECK_THROWS_AS(register_human_model({"linear", "again", &build_spring_person}), std::logic_error);
}

TEST_CASE("sim factory: built-in models, their choices and their errors") {
  HumanSpec lin;
  lin.linear = table1_person();
  lin.linear.motor_noise_n = 0.2;
  const auto a = make_human(lin);
  CHECK(a.step_s == Approx(1.0 / 16000.0));
  CHECK_FALSE(a.midpoint_plant);
  CHECK_FALSE(a.anthropometrics);
  // The factory's linear person is the LinearImpedanceHuman of those parameters
  // at the step's rate: identical trajectories with the same seed.
  auto p = lin.linear;
  p.sample_rate_hz = 16000.0;
  LinearImpedanceHuman direct(p);
  const ReachSpec reach;
  a.model->begin_trial(reach, 42);
  direct.begin_trial(reach, 42);
  const auto plant = plant_params(default_sim_session());
  for (int k = 0; k < 20000; ++k) {
    step_ideal_admittance(*a.model, plant, Vec2::Zero(), 1.0 / 16000.0);
    step_ideal_admittance(direct, plant, Vec2::Zero(), 1.0 / 16000.0);
  }
  CHECK(a.model->hand_position_m() == direct.hand_position_m());

  HumanSpec nm;
  nm.model = "neuromech";
  const auto b = make_human(nm);  // built-in defaults (= config/arm_model.yaml)
  CHECK(b.step_s == Approx(2.5e-4));  // integration.session_step_s: one arm step per 4 kHz sample
  CHECK(b.midpoint_plant);
  REQUIRE(b.anthropometrics);
  CHECK(b.anthropometrics->length_m[0] == Anthropometrics{}.length_m[0]);
  CHECK(b.config_yaml.find("session_step_s") != std::string::npos);
  nm.plant_step_s = 1.0 / 16000.0;  // manip_rt's sim backend: 4 kHz x 4 substeps
  CHECK(make_human(nm).step_s == Approx(1.0 / 16000.0));
  nm.plant_step_s = 1.0 / 12345.0;  // not a whole multiple of the arm's step
  CHECK_THROWS_AS(make_human(nm), ConfigError);
  nm.plant_step_s = 0.0;
  nm.feedback = "sometimes";
  CHECK_THROWS_AS(make_human(nm), UsageError);
  nm.feedback = "config";
  nm.arm_config = "/nonexistent/arm.yaml";
  CHECK_THROWS_AS(make_human(nm), ConfigError);
  HumanSpec unknown;
  unknown.model = "centaur";
  CHECK_THROWS_AS(make_human(unknown), UsageError);
}
