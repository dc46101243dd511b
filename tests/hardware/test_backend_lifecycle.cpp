// The backend lifecycle (hardware/backend.hpp): configure -> enable ->
// disable -> shutdown, out-of-order calls refused without side effects,
// shutdown idempotent and disabling first.
#include <catch2/catch.hpp>

#include <string>
#include <vector>

#include "manip/hardware/backend.hpp"
#include "manip/hardware/sim_backend.hpp"
#include "manip/runtime/config.hpp"

namespace hw = manip::hardware;
using hw::BackendState;

namespace {

// Records the hooks it receives; can be told to fail configure/enable.
class ProbeBackend final : public hw::Backend {
 public:
  std::vector<std::string> calls;
  bool fail_configure{false}, fail_enable{false};
  [[nodiscard]] std::string name() const override { return "probe"; }
  void read(manip::control::SensorReading&) override { calls.emplace_back("read"); }
  void write(const manip::control::ActuatorCommand&) override { calls.emplace_back("write"); }

 protected:
  void on_configure() override {
    calls.emplace_back("configure");
    if (fail_configure) throw hw::BackendError("probe: no drive on the bus");
  }
  void on_enable() override {
    calls.emplace_back("enable");
    if (fail_enable) throw hw::BackendError("probe: drive refused switch-on");
  }
  void on_disable() noexcept override { calls.emplace_back("disable"); }
  void on_shutdown() noexcept override { calls.emplace_back("shutdown"); }
};

}  // namespace

TEST_CASE("backend lifecycle: the normal order", "[backend][lifecycle]") {
  ProbeBackend b;
  CHECK(b.state() == BackendState::kUnconfigured);
  b.configure();
  CHECK(b.state() == BackendState::kInactive);
  b.enable();
  CHECK(b.state() == BackendState::kActive);
  b.disable();
  CHECK(b.state() == BackendState::kInactive);
  b.enable();  // re-enable after a disable (e.g. after a fault reset)
  b.shutdown();
  CHECK(b.state() == BackendState::kFinalized);
  CHECK(b.calls == std::vector<std::string>{"configure", "enable", "disable", "enable", "disable", "shutdown"});
  b.shutdown();  // idempotent
  b.disable();   // no-op when not active
  CHECK(b.calls.size() == 6);
}

TEST_CASE("backend lifecycle: out-of-order calls are refused and change nothing", "[backend][lifecycle]") {
  ProbeBackend b;
  CHECK_THROWS_AS(b.enable(), hw::BackendStateError);  // enable before configure
  CHECK(b.state() == BackendState::kUnconfigured);
  CHECK(b.calls.empty());
  b.configure();
  CHECK_THROWS_AS(b.configure(), hw::BackendStateError);  // twice
  b.enable();
  CHECK_THROWS_AS(b.enable(), hw::BackendStateError);
  CHECK_THROWS_AS(b.configure(), hw::BackendStateError);
  CHECK(b.state() == BackendState::kActive);
  b.shutdown();
  CHECK_THROWS_AS(b.configure(), hw::BackendStateError);  // finalized is final
  CHECK_THROWS_AS(b.enable(), hw::BackendStateError);
  try {
    b.enable();
  } catch (const hw::BackendStateError& e) {
    CHECK(std::string(e.what()).find("finalized") != std::string::npos);
    CHECK(e.exit_code() == manip::exit_code::kInternal);
  }
  CHECK(b.calls == std::vector<std::string>{"configure", "enable", "disable", "shutdown"});
}

TEST_CASE("backend lifecycle: a failed configure or enable leaves the state unchanged", "[backend][lifecycle]") {
  ProbeBackend b;
  b.fail_configure = true;
  CHECK_THROWS_AS(b.configure(), hw::BackendError);
  CHECK(b.state() == BackendState::kUnconfigured);
  b.fail_configure = false;
  b.fail_enable = true;
  b.configure();
  try {
    b.enable();
    FAIL("enable did not fail");
  } catch (const manip::Error& e) {
    CHECK(e.exit_code() == manip::exit_code::kBackend);
  }
  CHECK(b.state() == BackendState::kInactive);
  b.shutdown();  // from Inactive: no disable hook, only shutdown
  CHECK(b.calls == std::vector<std::string>{"configure", "configure", "enable", "shutdown"});
}

TEST_CASE("backend lifecycle: shutdown without configure releases nothing it never took", "[backend][lifecycle]") {
  ProbeBackend b;
  b.shutdown();
  CHECK(b.state() == BackendState::kFinalized);
  CHECK(b.calls.empty());
}

TEST_CASE("sim backend: disable zeroes the force and the drives", "[backend][lifecycle][sim_backend]") {
  const manip::runtime::RtConfig cfg;
  hw::SimBackend sim(cfg, cfg.sim, hw::make_sim_human(cfg, cfg.sim));
  CHECK_THROWS_AS(sim.enable(), hw::BackendStateError);
  sim.configure();
  sim.enable();
  manip::control::ActuatorCommand c;
  c.enable = true;
  c.f_motor_n = manip::Vec2(5.0, -3.0);
  sim.write(c);
  manip::control::SensorReading r;
  sim.read(r);
  sim.read(r);  // the held force acts from the next cycle
  CHECK(sim.enabled());
  CHECK(sim.applied_force_n().norm() > 0.0);
  sim.shutdown();
  CHECK_FALSE(sim.enabled());
  CHECK(sim.applied_force_n().norm() == 0.0);
  CHECK(sim.state() == BackendState::kFinalized);
}
