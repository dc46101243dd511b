// The `can` backend (include/manip/hardware/can_backend.hpp) against simulated
// CiA 402 drives on the in-process virtual bus: lifecycle, unit/axis mapping,
// the bus-budget refusal, start-up failures, faults mid-session (safe state
// within one control cycle, latched reason), safety inputs, the real-time path
// without allocation, and manip_rt --backend can --can-virtual completing a
// protocol whose log estimates like the sim backend's.
#include <catch2/catch.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "alloc_counter.hpp"
#include "sanitized.hpp"

#include "manip/can_frames_t.hpp"
#include "manip/canopen/error.hpp"
#include "manip/common/channels.hpp"
#include "manip/fault_t.hpp"
#include "manip/logging/event_log.hpp"
#include "manip/command_t.hpp"
#include "manip/control/controller.hpp"
#include "manip/estimation/session_estimator.hpp"
#include "manip/hardware/can_backend.hpp"
#include "manip/runtime/config.hpp"

#include "fixtures.hpp"

namespace hw = manip::hardware;
namespace cc = manip::canopen;
namespace bs = manip::control::backend_status;
using manip::Vec2;

namespace {

const std::string kSrc = MANIP_SOURCE_DIR;

manip::runtime::RtConfig rt_cfg() { return manip::runtime::load_rt_config(kSrc + "/config/rt.yaml"); }

cc::CanConfig can_cfg() {
  std::ifstream in(kSrc + "/config/can.yaml");
  std::stringstream ss;
  ss << in.rdbuf();
  std::string text = ss.str();
  // the shipped file with virtual: true (what --can-virtual does)
  const auto at = text.find("  virtual: false");
  REQUIRE(at != std::string::npos);
  text.replace(at, 16, "  virtual: true");
  cc::CanConfig c;
  std::vector<std::string> errors;
  const bool ok = cc::parse_config(text, "can.yaml", c, errors);
  INFO((errors.empty() ? std::string() : errors.front()));
  REQUIRE(ok);
  return c;
}

// The loop's side, without the controller: read, then at drive ticks write.
struct Loop {
  hw::CanBackend& b;
  manip::control::SensorReading r{};
  std::int64_t k{0};
  void cycle(const Vec2& f = Vec2::Zero()) {
    b.read(r);
    manip::control::ActuatorCommand c;
    c.f_motor_n = f;
    c.enable = true;
    c.send = (k % 2) == 0;  // 2 kHz drive ticks of the 4 kHz loop
    if (c.send) b.write(c);
    ++k;
  }
  // Cycles until a status bit in `mask` is raised; -1 if not within max.
  int until(std::uint32_t mask, int max) {
    for (int i = 1; i <= max; ++i) {
      cycle();
      if (r.status & mask) return i;
    }
    return -1;
  }
};

void started(hw::CanBackend& b) {
  b.configure();
  b.enable();
  REQUIRE(b.state() == hw::BackendState::kActive);
}

// The safe state: the detecting read() raised the status bit (the controller
// commands zero force in the same cycle) and sent Disable voltage + zero
// torque + SYNC on every bus (canopen tests: check_safe_state_after_fault);
// the drives act on it once it is off the wire, behind their own TPDOs (up to
// ~360 us at 1 Mbit/s): within one SYNC period (two 4 kHz cycles) neither
// simulated drive is in Operation enabled or applies force.
void check_safe_next_cycle(Loop& l) {
  l.cycle();
  l.cycle();
  for (int a = 0; a < 2; ++a) {
    INFO("axis " << a);
    CHECK(l.b.sim_drive(a)->state() != cc::cia402::State::OperationEnabled);
    CHECK(l.b.sim_drive(a)->applied_force_n() == 0.0);
  }
}

}  // namespace

TEST_CASE("can backend (virtual): configure leaves drives disabled, enable reaches Operation enabled", "[can_backend]") {
  const auto cfg = rt_cfg();
  hw::CanBackend b(cfg, cfg.sim, can_cfg());
  b.configure();
  REQUIRE(b.state() == hw::BackendState::kInactive);
  CHECK(b.budget_text().find("bus_x") != std::string::npos);
  for (int a = 0; a < 2; ++a) {
    CHECK(b.sim_drive(a)->nmt_state() == cc::NmtState::Operational);
    CHECK(b.sim_drive(a)->state() != cc::cia402::State::OperationEnabled);
    // the start-up wrote the heartbeat consumer 0x1016:01 = master node << 16 | ms
    CHECK(b.sim_drive(a)->od_value(0x1016, 1) == ((127u << 16) | 100u));
    CHECK(b.sim_drive(a)->od_value(0x6060, 0) == 10u);  // CST
  }
  b.enable();
  for (int a = 0; a < 2; ++a) {
    CHECK(b.sim_drive(a)->state() == cc::cia402::State::OperationEnabled);
    CHECK(b.sim_drive(a)->target_torque_permille() == 0);
  }
  Loop l{b};
  l.cycle();
  CHECK((l.r.status & bs::kDrivesEnabled) != 0);
  CHECK((l.r.status & (bs::kDriveFault | bs::kBackendError | bs::kHwEStopOpen)) == 0);
  b.disable();
  CHECK(b.sim_drive(0)->state() != cc::cia402::State::OperationEnabled);
  b.shutdown();
  CHECK(b.state() == hw::BackendState::kFinalized);
  CHECK(b.fault_reason().empty());
}

TEST_CASE("can backend (virtual): positions, velocities and forces mapped with units and signs", "[can_backend]") {
  const auto cfg = rt_cfg();
  auto can = can_cfg();
  can.drives[1].sign = -1;  // axis 2's drive counts the other way
  hw::CanBackend b(cfg, cfg.sim, can);
  started(b);
  Loop l{b};
  const Vec2 f_cmd(30.0, -20.0);
  for (int i = 0; i < 400; ++i) l.cycle(f_cmd);  // 100 ms
  // encoder counts -> workspace metres: the plant's true position within a
  // count (1 um) plus the motion during the TPDO latency (<= 2 cycles)
  const Vec2 x_true = b.plant()->true_position_workspace_m();
  const Vec2 v_true = b.plant()->true_velocity_workspace_mps();
  for (int a = 0; a < 2; ++a) {
    INFO("axis " << a);
    CHECK(std::abs(l.r.x_workspace_m[a] - x_true[a]) < 1e-6 + 2 * 250e-6 * std::abs(v_true[a]) + 1e-9);
    CHECK(std::abs(l.r.xd_workspace_mps[a] - v_true[a]) < 0.02 * std::abs(v_true[a]) + 1e-4);
    // N -> per mille (200 N rated, 0.2 N per count) -> N on the stage, sign restored
    CHECK(b.plant()->applied_force_n()[a] == Approx(f_cmd[a]).margin(0.1));
  }
  // the drive of axis 2 saw the negated torque
  CHECK(b.sim_drive(1)->target_torque_permille() == 100);  // -(-20 N) / 200 N * 1000
  CHECK(b.sim_drive(0)->target_torque_permille() == 150);
  CHECK(l.r.x_workspace_m[1] - b.plant()->true_position_workspace_m()[1] < 1e-3);
}

TEST_CASE("can backend: an over-budget configuration is refused at configure with the budget", "[can_backend]") {
  const auto cfg = rt_cfg();
  auto can = can_cfg();
  can.master.max_bus_load = 0.60;  // the shipped mapping needs 73.6 % worst case
  hw::CanBackend b(cfg, cfg.sim, can);
  try {
    b.configure();
    FAIL("over-budget configuration accepted");
  } catch (const hw::BackendError& e) {
    const std::string w = e.what();
    CHECK(e.exit_code() == 8);
    CHECK(w.find("max_bus_load") != std::string::npos);
    CHECK(w.find("bus_x") != std::string::npos);  // the budget table
  }
  CHECK(b.state() == hw::BackendState::kUnconfigured);
}

TEST_CASE("can backend: start-up failures are typed errors, nothing enabled", "[can_backend]") {
  const auto cfg = rt_cfg();
  SECTION("SDO abort on the PDO mapping") {
    hw::CanBackend b(cfg, cfg.sim, can_cfg());
    cc::SimulatedDrive* d = nullptr;
    b.before_startup = [&](cc::VirtualRig& rig) {
      d = &rig.drive(0);
      d->faults().reject_index = 0x1600;
      d->faults().reject_sub = 1;
      d->faults().reject_abort = 0x06040041;  // object cannot be mapped
    };
    try {
      b.configure();
      FAIL("start-up did not fail");
    } catch (const hw::BackendError& e) {
      CHECK(std::string(e.what()).find("06040041") != std::string::npos);
      CHECK(e.exit_code() == 8);
    }
    CHECK(b.state() == hw::BackendState::kUnconfigured);
  }
  SECTION("a drive that never boots") {
    hw::CanBackend b(cfg, cfg.sim, can_cfg());
    b.before_startup = [](cc::VirtualRig& rig) { rig.drive(1).faults().never_boot = true; };
    try {
      b.configure();
      FAIL("start-up did not fail");
    } catch (const hw::BackendError& e) {
      CHECK(std::string(e.what()).find("boot") != std::string::npos);
    }
  }
  SECTION("sim force sensor without the virtual bus") {
    auto can = can_cfg();
    can.backend.virtual_bus = false;
    can.backend.force_sensor = "sim";
    hw::CanBackend b(cfg, cfg.sim, can);
    CHECK_THROWS_AS(b.configure(), manip::ConfigError);
  }
  SECTION("SocketCAN interface missing (or no AF_CAN): exit 8 with the bus named") {
    auto can = can_cfg();
    can.backend.virtual_bus = false;
    can.buses[0].interface = "nosuchcan7";
    hw::CanBackend b(cfg, cfg.sim, can);
    try {
      b.configure();
      FAIL("started without the interface");
    } catch (const hw::BackendError& e) {
      CHECK(std::string(e.what()).find("CAN bus 'bus_x' (nosuchcan7)") != std::string::npos);
      CHECK(e.exit_code() == 8);
    }
    CHECK(b.state() == hw::BackendState::kUnconfigured);
  }
}

TEST_CASE("can backend: faults mid-session reach the safe state within one SYNC period with a latched reason", "[can_backend]") {
  const auto cfg = rt_cfg();
  hw::CanBackend b(cfg, cfg.sim, can_cfg());
  started(b);
  Loop l{b};
  for (int i = 0; i < 400; ++i) l.cycle(Vec2(5.0, 5.0));
  REQUIRE(l.r.status == bs::kDrivesEnabled);
  std::string reason_word;
  std::uint32_t bit = 0;
  int max_cycles = 8;
  bool acknowledgeable = true;  // the operator's FAULT_RESET can clear it (no restart)
  SECTION("drive enters Fault") {
    b.sim_drive(0)->enter_fault(0x2310, 0);  // continuous over-current
    bit = bs::kDriveFault;
    reason_word = "node 1";
  }
  SECTION("faulting EMCY") {
    b.sim_drive(1)->inject_emcy(0x3210, 0x05, false);  // DC link over-voltage: faults by the EMCY policy
    bit = bs::kDriveFault;
    reason_word = "EMCY";
  }
  SECTION("heartbeat loss") {
    b.sim_drive(1)->faults().heartbeat_stopped = true;
    bit = bs::kBackendError;
    reason_word = "heartbeat";
    max_cycles = 4 * 200;  // consumer time 150 ms
    acknowledgeable = false;
  }
  SECTION("TPDOs stop") {
    b.sim_drive(0)->faults().drop_all_tpdos = true;
    bit = bs::kBackendError;
    reason_word = "TPDO";
  }
  const int n = l.until(bit, max_cycles);
  INFO(b.fault_reason());
  REQUIRE(n > 0);
  CHECK(b.fault_reason().find(reason_word) != std::string::npos);
  check_safe_next_cycle(l);
  // Latched: the master holds the safe state and the reason until the
  // operator's reset. An acknowledgeable fault raised its bit in the
  // detecting cycle (the supervisor latches it) and is no longer "present",
  // so FAULT_RESET can be accepted; one that needs a restart stays present.
  for (int i = 0; i < 40; ++i) l.cycle();
  CHECK(b.drives().faulted());
  CHECK(b.fault_reason().find(reason_word) != std::string::npos);
  CHECK(((l.r.status & bit) != 0) == !acknowledgeable);
  CHECK(b.drives().fault_acknowledgeable() == acknowledgeable);
  for (int a = 0; a < 2; ++a) {
    CHECK(b.sim_drive(a)->state() != cc::cia402::State::OperationEnabled);
    CHECK(b.sim_drive(a)->applied_force_n() == 0.0);
  }
}

TEST_CASE("can backend: a warning EMCY (temperature class) is logged by the master, no fault", "[can_backend]") {
  const auto cfg = rt_cfg();
  hw::CanBackend b(cfg, cfg.sim, can_cfg());
  started(b);
  Loop l{b};
  for (int i = 0; i < 40; ++i) l.cycle();
  b.sim_drive(0)->inject_emcy(0x4310, 0x09, false);
  CHECK(l.until(bs::kDriveFault | bs::kBackendError | bs::kHwEStopOpen, 400) == -1);
  CHECK(b.fault_reason().empty());
  bool logged = false;
  auto& m = b.drives().master(0);
  for (std::size_t i = 0; i < m.log_count(); ++i)
    logged |= m.log_entry(i).code == cc::ErrorCode::EmcyWarning && m.log_entry(i).value == 0x4310;
  CHECK(logged);
}

TEST_CASE("can backend: e-stop / STO reported by the drive is a latched hardware e-stop", "[can_backend]") {
  const auto cfg = rt_cfg();
  auto can = can_cfg();
  can.backend.estop_statusword_bit = 14;  // the drive's manufacturer bit wired to the e-stop chain
  hw::CanBackend b(cfg, cfg.sim, can);
  started(b);
  Loop l{b};
  for (int i = 0; i < 40; ++i) l.cycle();
  REQUIRE((l.r.status & bs::kHwEStopOpen) == 0);
  b.sim_drive(1)->faults().statusword_extra = 1u << 14;
  const int n = l.until(bs::kHwEStopOpen, 4);  // next TPDO: within 2 SYNC periods
  REQUIRE(n > 0);
  CHECK(b.fault_reason().find("e-stop") != std::string::npos);
  CHECK(b.fault_reason().find("axis 1") != std::string::npos);
}

TEST_CASE("can backend: the real-time path does not allocate", "[can_backend][no_alloc]") {
  const auto cfg = rt_cfg();
  auto can = can_cfg();
  // Raw-frame recording on, with a queue nobody drains here: the drop path too.
  can.backend.record_raw_frames = true;
  can.backend.raw_queue_frames = 1024;
  hw::CanBackend b(cfg, cfg.sim, can);
  started(b);
  Loop l{b};
  for (int i = 0; i < 100; ++i) l.cycle(Vec2(3.0, -3.0));
  manip::test::AllocCounts got;
  bool faulted = false, raised = false;
  {
    const manip::test::ThreadAllocScope s;
    for (int i = 0; i < 4000; ++i) l.cycle(Vec2(3.0, -3.0));
    b.sim_drive(0)->enter_fault(0x2310, 0);  // the fault path too
    for (int i = 0; i < 20; ++i) {
      l.cycle();
      raised |= (l.r.status & bs::kDriveFault) != 0;
    }
    faulted = b.drives().faulted();
    b.request_fault_reset();  // ... and the operator's reset, re-enable included
    for (int i = 0; i < 400; ++i) l.cycle(Vec2(3.0, -3.0));
    got = s.counts();
  }
  CHECK(got.news == 0);
  CHECK(raised);
  CHECK(faulted);
  CHECK(l.r.status == bs::kDrivesEnabled);
  CHECK(b.raw_frames_dropped() > 0);
  CHECK(b.recorder()->size_approx() == b.recorder()->capacity());
}

namespace {
int run_app(const std::string& args, std::string& output) {
  return manip::testutil::run_command(
      "cd " + kSrc + " && " + std::string(MANIP_BINARY_DIR) + "/apps/manip_rt " + args, &output);
}
}  // namespace

TEST_CASE("manip_rt --backend can --can-virtual completes a protocol that estimates like --backend sim",
          "[can_backend][session][full]") {
  if (!std::filesystem::exists(std::string(MANIP_BINARY_DIR) + "/apps/manip_rt")) {
    WARN("manip_rt not built: skipped (ninja manip_rt)");
    return;
  }
  if (kSanitized) {
    WARN("skipped under sanitizers (two 12-movement sessions + estimation)");
    return;
  }
  const std::string dir = std::filesystem::temp_directory_path().string();
  const std::string log_can = dir + "/manip_can_session_" + std::to_string(::getpid()) + ".lcm";
  const std::string log_sim = dir + "/manip_sim_session_" + std::to_string(::getpid()) + ".lcm";
  const std::string common = " --movements 12 --afap --lcm-url none --quiet --force --exit-on-fault";
  std::string out;
  const int rc_can = run_app("--backend can --can-virtual" + common + " --out " + log_can, out);
  INFO(out);
  REQUIRE(rc_can == 0);
  const int rc_sim = run_app("--backend sim" + common + " --out " + log_sim, out);
  REQUIRE(rc_sim == 0);
  namespace est = manip::estimation;
  est::EstimatorSettings es;
  es.methods = {est::default_method()};
  const auto rc = est::estimate_log(log_can, es);
  const auto rs = est::estimate_log(log_sim, es);
  std::filesystem::remove(log_can);
  std::filesystem::remove(log_sim);
  const est::Summary* sc = nullptr;
  const est::Summary* ss = nullptr;
  for (const auto& s : rc.summaries)
    if (s.method == est::default_method() && s.group.is_session()) sc = &s;
  for (const auto& s : rs.summaries)
    if (s.method == est::default_method() && s.group.is_session()) ss = &s;
  REQUIRE(sc);
  REQUIRE(ss);
  CHECK(rc.n_perturbed == rs.n_perturbed);
  CHECK(rc.n_perturbed > 0);
  const auto cfg = rt_cfg();
  const manip::Mat2 k_true = cfg.sim.human.k_npm, d_true = cfg.sim.human.d_nspm;
  std::ostringstream msg;
  msg << "can  D " << sc->d_nspm << "\n K " << sc->k_npm << "\nsim  D " << ss->d_nspm << "\n K " << ss->k_npm
      << "\n|dK| " << (sc->k_npm - ss->k_npm).norm() << " N/m, |dD| " << (sc->d_nspm - ss->d_nspm).norm() << " N s/m";
  WARN(msg.str());
  // The tolerance of the sim backend's rendering test (tests/integration/test_estimate_rt.cpp):
  // 20 % of the truth's Frobenius norm, for K and for D.
  CHECK((sc->k_npm - ss->k_npm).norm() < 0.20 * k_true.norm());
  CHECK((sc->d_nspm - ss->d_nspm).norm() < 0.20 * d_true.norm());
}

// Through run_session (controller, supervisor, logger): a fault injected into
// a simulated drive mid-session ends the session with the supervisor's
// backend / hardware_estop fault, the drives safe, the reason latched.
#include "offline_run.hpp"
#include "manip/runtime/session.hpp"

namespace {
class Injecting final : public hw::Backend {
 public:
  Injecting(hw::CanBackend& in, std::int64_t at, std::function<void(hw::CanBackend&)> inject)
      : in_(in), at_(at), inject_(std::move(inject)) {}
  [[nodiscard]] std::string name() const override { return "can"; }
  [[nodiscard]] bool supports_as_fast_as_possible() const override { return true; }
  void read(manip::control::SensorReading& out) override {
    if (++n_ == at_) inject_(in_);
    in_.read(out);
    if (out.status & (bs::kDriveFault | bs::kBackendError | bs::kHwEStopOpen) && first_fault_ < 0) first_fault_ = n_;
  }
  void write(const manip::control::ActuatorCommand& c) override { in_.write(c); }
  void display(const manip::control::DisplayCue& c) override { in_.display(c); }
  void request_fault_reset() noexcept override { in_.request_fault_reset(); }
  hw::BackendLogTap* log_tap() noexcept override { return in_.log_tap(); }
  std::int64_t first_fault_{-1};

 private:
  void on_configure() override { in_.configure(); }
  void on_enable() override { in_.enable(); }
  void on_disable() noexcept override { in_.disable(); }
  void on_shutdown() noexcept override { in_.shutdown(); }
  hw::CanBackend& in_;
  std::int64_t n_{0}, at_;
  std::function<void(hw::CanBackend&)> inject_;
};
}  // namespace

TEST_CASE("can backend in run_session: a drive fault mid-session ends it with the backend fault", "[can_backend][session]") {
  const auto base = rt_cfg();
  const auto cfg = manip::runtime::load_rt_config(kSrc + "/config/rt.yaml", manip::runtime::trials_overrides(base, 2));
  auto can = can_cfg();
  can.backend.estop_statusword_bit = 14;
  std::uint32_t want = 0;
  std::string word;
  std::function<void(hw::CanBackend&)> inject;
  SECTION("drive Fault") {
    inject = [](hw::CanBackend& b) { b.sim_drive(1)->enter_fault(0x2310, 0); };
    want = manip::control::fault::kBackend;
    word = "Fault";
  }
  SECTION("heartbeat loss") {
    inject = [](hw::CanBackend& b) { b.sim_drive(0)->faults().heartbeat_stopped = true; };
    want = manip::control::fault::kBackend;
    word = "heartbeat";
  }
  SECTION("e-stop chain") {
    inject = [](hw::CanBackend& b) { b.sim_drive(0)->faults().statusword_extra = 1u << 14; };
    want = manip::control::fault::kHardwareEStop;
    word = "e-stop";
  }
  SECTION("STO without a CANopen fault: the drive falls to Switch on disabled") {
    inject = [](hw::CanBackend& b) { b.sim_drive(1)->faults().power_stage_lost = true; };
    want = manip::control::fault::kHardwareEStop;
    word = "Operation enabled";
  }
  hw::CanBackend can_b(cfg, cfg.sim, can);
  Injecting b(can_b, 8000, inject);  // 2 s into the session
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("manip_can_fault_" + std::to_string(::getpid()) + ".lcm")).string();
  auto opt = offline_run_options(path);
  opt.exit_on_fault = true;
  std::ostringstream out;
  const auto rep = manip::runtime::run_session(cfg, b, opt, out);
  std::filesystem::remove(path);
  INFO(out.str());
  CHECK(rep.exit_code == 7);
  CHECK((rep.fault_flags & want) != 0);
  CHECK(can_b.fault_reason().find(word) != std::string::npos);
  REQUIRE(b.first_fault_ > 0);
  for (int a = 0; a < 2; ++a) CHECK(can_b.sim_drive(a)->applied_force_n() == 0.0);
}

// ---------------------------------------------------------------------------
// Operator fault reset (docs/hardware.md "Operator fault reset").

namespace {
// The loop as manip_rt runs it (runtime::RtCycle: read -> Controller::step ->
// write, the supervisor's accepted FAULT_RESET -> backend.request_fault_reset),
// cycle by cycle, with the operator's commands through the command queue.
struct SupervisedLoop {
  explicit SupervisedLoop(const manip::runtime::RtConfig& c, hw::CanBackend& backend)
      : cfg(c),
        log(c.loop.log_queue_capacity),
        bus(c.loop.bus_queue_capacity),
        cmds(c.loop.command_queue_capacity),
        ctl(c, {&log, &bus, &cmds}, manip::control::ControllerOptions{false, false, 0, 1'700'000'000'000'000}),
        b(backend),
        body(backend, ctl) {}
  const manip::runtime::RtConfig& cfg;
  manip::runtime::RecordQueue log, bus;
  manip::runtime::CommandQueue cmds;
  manip::control::Controller ctl;
  hw::CanBackend& b;
  manip::runtime::RtCycle body;
  std::int64_t k{0};
  std::vector<manip::control::CommandResultRecord> results;
  std::vector<manip::control::FaultRecord> faults;
  // The loop only (no draining): for the allocation counter.
  void cycles(int n) {
    for (int i = 0; i < n; ++i) body.run_cycle(k++, false);
  }
  void run(int n) {
    cycles(n);
    drain();
  }
  void drain() {
    manip::control::LoopRecord r;
    while (log.try_pop(r)) {
      if (auto* c = std::get_if<manip::control::CommandResultRecord>(&r)) results.push_back(*c);
      if (auto* f = std::get_if<manip::control::FaultRecord>(&r)) faults.push_back(*f);
    }
    while (bus.try_pop(r)) {
    }
  }
  void command(std::int8_t kind) {
    manip::control::Command c;
    c.kind = kind;
    c.seq = k;
    REQUIRE(cmds.try_push(c));
  }
  // Cycles until pred() holds; -1 if not within max.
  template <class P>
  int until(P pred, int max) {
    for (int i = 1; i <= max; ++i) {
      run(1);
      if (pred()) return i;
    }
    return -1;
  }
  manip::control::Mode mode() const { return ctl.mode(); }
};
}  // namespace

TEST_CASE("can backend: operator FAULT_RESET clears a drive fault, re-enables the drives and torque flows again",
          "[can_backend][fault_reset]") {
  using manip::control::Mode;
  const auto cfg = rt_cfg();
  hw::CanBackend b(cfg, cfg.sim, can_cfg());
  started(b);
  SupervisedLoop s(cfg, b);
  s.run(2000);  // 0.5 s: INIT -> RUNNING (autostart), the person holds the handle
  REQUIRE(s.mode() == Mode::kRunning);
  REQUIRE(s.body.reading().status == bs::kDrivesEnabled);
  cc::SimulatedDrive& d = *b.sim_drive(0);

  d.enter_fault(0x2310, 0);  // over-current: CiA 402 Fault + faulting EMCY
  REQUIRE(s.until([&] { return s.mode() == Mode::kFault; }, 8) > 0);
  s.run(2);  // within one SYNC period: both drives disabled, no force
  for (int a = 0; a < 2; ++a) {
    CHECK(b.sim_drive(a)->state() != cc::cia402::State::OperationEnabled);
    CHECK(b.sim_drive(a)->applied_force_n() == 0.0);
  }
  REQUIRE(s.faults.size() == 1);
  CHECK((s.faults[0].new_flags & manip::control::fault::kBackend) != 0);

  // Nobody resets: the drive stays in Fault, bit 7 is never set, the
  // supervisor stays in FAULT (safe law) and the master keeps zero torque.
  s.run(4000);
  CHECK(d.state() == cc::cia402::State::Fault);
  CHECK(d.fault_resets() == 0);
  CHECK((d.controlword() & cc::cia402::cw::kFaultResetBit) == 0);
  CHECK(s.mode() == Mode::kFault);
  CHECK((s.body.reading().status & bs::kDriveFault) == 0);  // latched, acknowledgeable: not "present"

  // The operator's FAULT_RESET: accepted, one rising edge, Switch on
  // disabled, transitions 2-3-4 back to Operation enabled (within
  // enable_timeout_ms), the session held in PAUSED until RESUME.
  s.command(manip::command_t::FAULT_RESET);
  s.run(1);
  REQUIRE_FALSE(s.results.empty());
  CHECK(s.results.back().kind == manip::command_t::FAULT_RESET);
  CHECK(s.results.back().accepted);
  CHECK(s.mode() == Mode::kPaused);
  const int n = s.until([&] { return (s.body.reading().status & bs::kDrivesEnabled) != 0; }, 4 * 500);
  INFO("cycles to Operation enabled after the reset: " << n);
  REQUIRE(n > 0);
  CHECK(d.fault_resets() == 1);  // exactly one edge
  CHECK(d.state() == cc::cia402::State::OperationEnabled);
  CHECK_FALSE(b.drives().faulted());
  CHECK(b.fault_reason().empty());  // acknowledged: the next fault gets a fresh reason
  CHECK(s.mode() == Mode::kPaused);  // hold: admittance, no trials
  s.command(manip::command_t::RESUME);
  double max_force = 0;
  for (int i = 0; i < 4000; ++i) {
    s.run(1);
    max_force = std::max(max_force, std::abs(d.applied_force_n()));
  }
  CHECK(s.mode() == Mode::kRunning);
  CHECK(s.body.reading().status == bs::kDrivesEnabled);
  CHECK(max_force > 0.5);  // torque flows again: the admittance renders the person's push
  CHECK(s.faults.size() == 1);
}

TEST_CASE("can backend: a reset that cannot clear never does - a fault that needs a restart refuses the reset",
          "[can_backend][fault_reset]") {
  using manip::control::Mode;
  const auto cfg = rt_cfg();
  hw::CanBackend b(cfg, cfg.sim, can_cfg());
  started(b);
  SupervisedLoop s(cfg, b);
  s.run(2000);
  REQUIRE(s.mode() == Mode::kRunning);

  SECTION("the drive's cause persists: one edge, still Fault, raised again with its reason") {
    cc::SimulatedDrive& d = *b.sim_drive(1);
    d.faults().fault_persists = true;
    d.enter_fault(0x4310, 0);  // drive over-temperature (a warning EMCY, but the drive trips: Fault)
    REQUIRE(s.until([&] { return s.mode() == Mode::kFault; }, 8) > 0);
    s.run(400);
    s.command(manip::command_t::FAULT_RESET);
    s.run(1);
    REQUIRE(s.results.back().accepted);
    // fault_reset_timeout_ms (20 ms) later: raised again, with the reason
    const int back = s.until([&] { return s.mode() == Mode::kFault; }, 4 * 100);
    REQUIRE(back > 0);
    CHECK(back >= 4 * 20);
    CHECK(d.fault_resets() == 0);
    CHECK(d.state() == cc::cia402::State::Fault);
    INFO("reason: " << b.fault_reason() << "; supervisor faults " << s.faults.size() << ", last flags " << s.faults.back().new_flags);
    CHECK(b.fault_reason().find("fault reset did not clear") != std::string::npos);
    CHECK(b.fault_reason().find("node 1") != std::string::npos);
    // No further edges behind the operator's back.
    int edges = 0;
    std::uint16_t prev = d.controlword();
    for (int i = 0; i < 2000; ++i) {
      s.run(1);
      const std::uint16_t c = d.controlword();
      edges += (c & 0x80) && !(prev & 0x80);
      prev = c;
    }
    CHECK(edges == 0);
    CHECK(d.state() == cc::cia402::State::Fault);
    // The cause gone, a second reset clears it.
    d.faults().fault_persists = false;
    s.command(manip::command_t::FAULT_RESET);
    s.run(1);
    CHECK(s.results.back().accepted);
    REQUIRE(s.until([&] { return (s.body.reading().status & bs::kDrivesEnabled) != 0; }, 4 * 500) > 0);
    CHECK(d.fault_resets() == 1);
    CHECK(d.state() == cc::cia402::State::OperationEnabled);
  }
  SECTION("heartbeat loss: condition present, reset refused, drives stay disabled") {
    b.sim_drive(0)->faults().heartbeat_stopped = true;
    REQUIRE(s.until([&] { return s.mode() == Mode::kFault; }, 4 * 200) > 0);
    s.run(40);
    s.command(manip::command_t::FAULT_RESET);
    s.run(1);
    REQUIRE_FALSE(s.results.empty());
    CHECK_FALSE(s.results.back().accepted);
    CHECK(s.results.back().reason == manip::control::Reject::kConditionPresent);
    s.run(400);
    CHECK(s.mode() == Mode::kFault);
    CHECK(b.drives().faulted());
    for (int a = 0; a < 2; ++a) CHECK(b.sim_drive(a)->applied_force_n() == 0.0);
  }
}

// ---------------------------------------------------------------------------
// E-stop / STO without a CANopen fault (docs/hardware.md "Fault policy"): a
// drive that leaves Operation enabled without the master's command (power
// stage lost, STO, quick stop, any other state) disarms the enable intent of
// both drives; nothing re-energises when the power comes back, only the
// operator's FAULT_RESET (IEC 60204-1, emergency stop: resetting the e-stop shall
// not restart the machine).

namespace {
// Per cycle: no drive back in Operation enabled, no torque on either RPDO.
struct Watch {
  int op_enabled_cycles{0};
  int torque_cycles{0};
  double max_force{0};
  void see(hw::CanBackend& b) {
    for (int a = 0; a < 2; ++a) {
      const cc::SimulatedDrive& d = *b.sim_drive(a);
      op_enabled_cycles += d.state() == cc::cia402::State::OperationEnabled;
      torque_cycles += d.target_torque_permille() != 0;
      max_force = std::max(max_force, std::abs(d.applied_force_n()));
    }
  }
};
// The supervised loop with the counting allocator around the loop cycles
// only (the drain is the logger's side).
struct Counted {
  Counted(SupervisedLoop& loop, hw::CanBackend& backend) : s(loop), b(backend) {}
  SupervisedLoop& s;
  hw::CanBackend& b;
  long news{0};
  Watch w;
  bool watch{false};
  void run(int n) {
    for (int i = 0; i < n; ++i) {
      {
        const manip::test::ThreadAllocScope scope;
        s.cycles(1);
        news += scope.counts().news;
      }
      if (watch) w.see(b);
      if ((i & 255) == 255) drain();
    }
    drain();
  }
  void drain() {
    s.drain();
    hw::BackendFaultNote note;
    while (b.next_fault_note(note)) notes.push_back(note);
  }
  std::vector<hw::BackendFaultNote> notes;
  template <class P>
  int until(P pred, int max) {
    for (int i = 1; i <= max; ++i) {
      run(1);
      if (pred()) return i;
    }
    return -1;
  }
};
bool safe_mode(manip::control::Mode m) { return m == manip::control::Mode::kFault || m == manip::control::Mode::kEStop; }
}  // namespace

TEST_CASE("can backend: after an e-stop / STO without a CANopen fault the drives stay disabled until the operator's "
          "FAULT_RESET", "[can_backend][estop][fault_reset][no_alloc]") {
  using manip::control::Mode;
  using S = cc::cia402::State;
  const auto cfg = rt_cfg();
  hw::CanBackend b(cfg, cfg.sim, can_cfg());  // shipped e-stop detection: estop_on_voltage_loss only
  started(b);
  SupervisedLoop s(cfg, b);
  Counted c{s, b};
  c.run(2000);
  REQUIRE(s.mode() == Mode::kRunning);
  REQUIRE(s.body.reading().status == bs::kDrivesEnabled);
  cc::SimulatedDrive& d = *b.sim_drive(0);
  S falls_to = S::SwitchOnDisabled;
  SECTION("the drive falls to Switch on disabled") { falls_to = S::SwitchOnDisabled; }
  SECTION("the drive falls to Ready to switch on") { falls_to = S::ReadyToSwitchOn; }
  SECTION("the drive stays in Operation enabled with 0x6041 bit 4 (voltage enabled) off") { falls_to = S::OperationEnabled; }
  d.faults().power_loss_state = falls_to;
  d.faults().power_stage_lost = true;  // e-stop pressed: STO on the drive of axis 0
  INFO("power loss state " << cc::cia402::to_string(falls_to));
  const int n = c.until([&] { return safe_mode(s.mode()); }, 8);
  INFO("reason: " << b.fault_reason());
  CHECK(n > 0);  // latched in the detecting cycle (the next TPDO)
  c.run(2);        // within one SYNC period: both drives disabled (one axis alone moving is unsafe)
  for (int a = 0; a < 2; ++a) {
    CHECK(b.sim_drive(a)->state() != S::OperationEnabled);
    CHECK(b.sim_drive(a)->applied_force_n() == 0.0);
  }
  // The reason: the master's (the drive left Operation enabled by itself)
  // or, when the drive still reported Operation enabled with bit 4 off, the
  // backend's e-stop / STO text.
  CHECK((b.fault_reason().find("Operation enabled") != std::string::npos ||
         b.fault_reason().find("safe torque off") != std::string::npos));
  c.run(400);
  // The chain closes again (power back) and nobody resets: 1 s, nothing
  // re-energises, only zero torque on the wire, the supervisor stays latched.
  d.faults().power_stage_lost = false;
  c.watch = true;
  c.run(4000);
  c.watch = false;
  CHECK(c.w.op_enabled_cycles == 0);
  CHECK(c.w.torque_cycles == 0);
  CHECK(c.w.max_force == 0.0);
  CHECK(safe_mode(s.mode()));
  CHECK((s.body.reading().status & bs::kDrivesEnabled) == 0);
  CHECK(d.state() != S::OperationEnabled);
  CHECK(b.sim_drive(1)->state() != S::OperationEnabled);
  bool noted = false;
  for (const auto& note : c.notes)
    noted |= note.text.find("Operation enabled") != std::string::npos || note.text.find("safe torque off") != std::string::npos;
  CHECK(noted);  // the reason went through the fault-note path (fault_t.reason)

  // The operator's FAULT_RESET: accepted, transitions 2-3-4, PAUSED until RESUME.
  s.command(manip::command_t::FAULT_RESET);
  c.run(1);
  REQUIRE_FALSE(s.results.empty());
  CHECK(s.results.back().kind == manip::command_t::FAULT_RESET);
  CHECK(s.results.back().accepted);
  CHECK(s.mode() == Mode::kPaused);
  const int m = c.until([&] { return (s.body.reading().status & bs::kDrivesEnabled) != 0; }, 4 * 500);
  INFO("cycles to Operation enabled after the reset: " << m);
  REQUIRE(m > 0);
  CHECK(d.state() == S::OperationEnabled);
  CHECK(b.sim_drive(1)->state() == S::OperationEnabled);
  CHECK(s.mode() == Mode::kPaused);
  s.command(manip::command_t::RESUME);
  c.watch = true;
  c.w = Watch{};
  c.run(4000);
  CHECK(s.mode() == Mode::kRunning);
  CHECK(s.body.reading().status == bs::kDrivesEnabled);
  CHECK(c.w.max_force > 0.5);  // torque flows again
  CHECK(c.news == 0);          // the whole sequence without an allocation in the loop
}

TEST_CASE("can backend: FAULT_RESET while the e-stop chain is still open is refused, the drives stay disabled",
          "[can_backend][estop][fault_reset]") {
  using manip::control::Mode;
  using S = cc::cia402::State;
  const auto cfg = rt_cfg();
  auto can = can_cfg();
  SECTION("chain on 0x60FD (TPDO2)") {
    can.backend.estop_input_bit = 16;
    can.backend.estop_input_open_high = false;
    for (auto& dc : can.drives) {
      dc.tpdo2 = cc::PdoMapping{};
      dc.tpdo2.add(cc::PdoObject::DigitalInputs);
    }
  }
  SECTION("chain on a manufacturer statusword bit") { can.backend.estop_statusword_bit = 14; }
  hw::CanBackend b(cfg, cfg.sim, can);
  started(b);
  SupervisedLoop s(cfg, b);
  Counted c{s, b};
  c.run(2000);
  REQUIRE(s.mode() == Mode::kRunning);
  cc::SimulatedDrive& d = *b.sim_drive(1);
  auto chain = [&](bool open) {
    // The contact the backend reads, and the STO it drives.
    if (can.backend.estop_input_bit >= 0) {
      if (open) d.faults().digital_inputs &= ~(1u << 16);
      else d.faults().digital_inputs |= 1u << 16;
    } else {
      d.faults().statusword_extra = open ? std::uint16_t(1u << 14) : std::uint16_t(0);
    }
    d.faults().power_stage_lost = open;
  };
  chain(true);
  REQUIRE(c.until([&] { return safe_mode(s.mode()); }, 8) > 0);
  c.run(40);
  for (int a = 0; a < 2; ++a) CHECK(b.sim_drive(a)->state() != S::OperationEnabled);
  CHECK((s.body.reading().status & bs::kHwEStopOpen) != 0);  // present while open
  s.command(manip::command_t::FAULT_RESET);
  c.run(1);
  REQUIRE_FALSE(s.results.empty());
  CHECK_FALSE(s.results.back().accepted);
  CHECK(s.results.back().reason == manip::control::Reject::kConditionPresent);
  CHECK((s.results.back().detail & manip::control::fault::kHardwareEStop) != 0);
  c.watch = true;
  c.run(4000);  // still open: nothing moves
  chain(false);
  c.run(4000);  // closed again, nobody reset: nothing moves either
  c.watch = false;
  CHECK(c.w.op_enabled_cycles == 0);
  CHECK(c.w.torque_cycles == 0);
  CHECK(c.w.max_force == 0.0);
  CHECK(safe_mode(s.mode()));
  s.command(manip::command_t::FAULT_RESET);
  c.run(1);
  CHECK(s.results.back().accepted);
  REQUIRE(c.until([&] { return (s.body.reading().status & bs::kDrivesEnabled) != 0; }, 4 * 500) > 0);
  CHECK(s.mode() == Mode::kPaused);
  CHECK(c.news == 0);
}

TEST_CASE("can backend: a reset the voltage-only detection cannot refuse does not enable later by itself",
          "[can_backend][estop][fault_reset]") {
  // With only 0x6041 bit 4 (estop_on_voltage_loss), a drive in Switch on
  // disabled cannot tell whether the chain is closed: the reset is accepted,
  // the drive cannot switch on without power (transition 3), the enable times
  // out (enable_timeout_ms) and faults again; when the power comes back later,
  // nothing re-energises until the next reset.
  using manip::control::Mode;
  using S = cc::cia402::State;
  const auto cfg = rt_cfg();
  hw::CanBackend b(cfg, cfg.sim, can_cfg());
  started(b);
  SupervisedLoop s(cfg, b);
  Counted c{s, b};
  c.run(2000);
  cc::SimulatedDrive& d = *b.sim_drive(0);
  d.faults().power_stage_lost = true;
  REQUIRE(c.until([&] { return safe_mode(s.mode()); }, 8) > 0);
  c.run(400);
  s.command(manip::command_t::FAULT_RESET);
  c.run(1);
  REQUIRE(s.results.back().accepted);
  const int back = c.until([&] { return safe_mode(s.mode()); }, 4 * 600);
  INFO("reason: " << b.fault_reason());
  REQUIRE(back > 0);
  CHECK(b.fault_reason().find("in time") != std::string::npos);
  CHECK(d.state() != S::OperationEnabled);
  d.faults().power_stage_lost = false;  // power back, nobody resets
  c.watch = true;
  c.run(4000);
  CHECK(c.w.op_enabled_cycles == 0);
  CHECK(c.w.torque_cycles == 0);
  CHECK(safe_mode(s.mode()));
  s.command(manip::command_t::FAULT_RESET);
  c.run(1);
  CHECK(s.results.back().accepted);
  c.watch = false;
  REQUIRE(c.until([&] { return (s.body.reading().status & bs::kDrivesEnabled) != 0; }, 4 * 500) > 0);
  CHECK(c.news == 0);
}

TEST_CASE("can backend in run_session: the CANopen reason and the raw CAN traffic are in the log",
          "[can_backend][session][log]") {
  const auto base = rt_cfg();
  const auto cfg = manip::runtime::load_rt_config(kSrc + "/config/rt.yaml", manip::runtime::trials_overrides(base, 2));
  auto can = can_cfg();
  can.backend.record_raw_frames = true;
  hw::CanBackend can_b(cfg, cfg.sim, can);
  // over-current with Copley's event status bit 0 (short circuit detected)
  Injecting b(can_b, 8000, [](hw::CanBackend& x) { x.sim_drive(1)->enter_fault(0x2310, 0x1); });
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("manip_can_log_" + std::to_string(::getpid()) + ".lcm")).string();
  auto opt = offline_run_options(path);
  opt.exit_on_fault = true;
  std::ostringstream out;
  const auto rep = manip::runtime::run_session(cfg, b, opt, out);
  INFO(out.str());
  REQUIRE(rep.exit_code == 7);

  std::vector<manip::fault_t> faults;
  std::int64_t frames = 0, batches = 0, dropped = -1, last_cycle = -1;
  std::int64_t startup_frames = 0, sdo_in_loop = 0, sdo_at_startup = 0, emcy_cycle = -2, fault_tpdo_cycle = -2;
  std::int64_t syncs[2] = {0, 0}, tpdo1[2] = {0, 0};
  std::vector<std::string> ifaces;
  {
    manip::logging::EventLogReader rd(path);
    manip::logging::RawEvent ev;
    while (rd.next(ev)) {
      const auto n = static_cast<int>(ev.data.size());
      if (ev.channel == manip::channels::kFault) {
        manip::fault_t f;
        REQUIRE(f.decode(ev.data.data(), 0, n) == n);
        faults.push_back(f);
      } else if (ev.channel == manip::channels::kState) {
        manip::state_t st;
        REQUIRE(st.decode(ev.data.data(), 0, n) == n);
        last_cycle = st.cycle;
      } else if (ev.channel == manip::channels::kCanRaw) {
        manip::can_frames_t m;
        REQUIRE(m.decode(ev.data.data(), 0, n) == n);
        ++batches;
        frames += m.n;
        dropped = m.dropped_total;
        ifaces = m.interfaces;
        for (int i = 0; i < m.n; ++i) {
          const bool tx = m.flags[i] & manip::can_frames_t::FLAG_TX;
          const std::uint32_t id = static_cast<std::uint32_t>(m.id[i]);
          const int bus = m.iface[i];
          REQUIRE((bus == 0 || bus == 1));
          const bool sdo = (id & 0x780) == 0x580 || (id & 0x780) == 0x600;
          if (m.cycle[i] < 0) {
            ++startup_frames;
            sdo_at_startup += sdo;
          } else {
            sdo_in_loop += sdo;
            if (tx && id == 0x080) ++syncs[bus];
            if (!tx && id == 0x181) ++tpdo1[bus];
            if (!tx && id == 0x081 && bus == 1 && emcy_cycle == -2) emcy_cycle = m.cycle[i];
            // statusword (first 2 bytes of TPDO1) with the CiA 402 Fault bit 3
            if (!tx && id == 0x181 && bus == 1 && fault_tpdo_cycle == -2 && (m.data[i][0] & 0x08))
              fault_tpdo_cycle = m.cycle[i];
          }
        }
      }
    }
  }
  std::filesystem::remove(path);

  // The decoded CANopen reason is in the supervisor's fault record of the cycle.
  REQUIRE_FALSE(faults.empty());
  INFO("fault reason: " << faults.front().reason);
  CHECK(faults.front().reason.find("backend") == 0);
  CHECK(faults.front().reason.find("; can backend: node 1: ") != std::string::npos);
  CHECK(faults.front().reason.find("Fault (statusword 0x") != std::string::npos);
  CHECK(rep.log.backend_notes >= 1);
  // After the session, Copley's event status register (0x1002) of each drive, read at shutdown
  bool event_status = false;
  for (const auto& f : faults)
    event_status |= f.cycle == -1 && f.reason.find("can backend: node 1: event status register 0x1002") == 0 &&
                    f.reason.find("short circuit detected") != std::string::npos;
  CHECK(event_status);

  // Raw traffic: every frame, candump-like, aligned with the states' cycles.
  INFO("raw frames " << frames << " in " << batches << " batches; start-up " << startup_frames << "; SYNC " << syncs[0]
                     << "/" << syncs[1] << ", TPDO1 " << tpdo1[0] << "/" << tpdo1[1] << "; last cycle " << last_cycle);
  CHECK(ifaces == std::vector<std::string>{"can0", "can1"});
  CHECK(dropped == 0);
  CHECK(frames == rep.log.raw_frames);
  CHECK(sdo_at_startup > 50);  // the SDO start-up list (both drives)
  CHECK(sdo_in_loop == 0);     // never an SDO in the cyclic phase
  for (int bus = 0; bus < 2; ++bus) {
    // one SYNC per drive tick (2 kHz of the 4 kHz loop) up to the fault,
    // then the master's safe SYNCs until the loop stops
    CHECK(std::abs(syncs[bus] - (last_cycle + 1) / 2) <= 4);
    CHECK(std::abs(tpdo1[bus] - syncs[bus]) <= 4);
  }
  // The TPDO reporting Fault was received in the very cycle the fault record
  // names; the drive's EMCY (0x2310) is recorded too.
  CHECK(fault_tpdo_cycle == faults.front().cycle);
  CHECK(emcy_cycle >= faults.front().cycle);
}

namespace {
// A backend's log tap with notes handed in by the test.
struct FakeTap final : hw::BackendLogTap {
  std::vector<hw::BackendFaultNote> notes;
  bool next_fault_note(hw::BackendFaultNote& out) override {
    if (notes.empty()) return false;
    out = notes.front();
    notes.erase(notes.begin());
    return true;
  }
};
manip::state_t state_at(std::int64_t cycle, std::uint32_t flags) {
  manip::state_t s{};
  s.cycle = cycle;
  s.utime = 1'700'000'000'000'000 + cycle * 250;
  s.fault_flags = static_cast<std::int32_t>(flags);
  return s;
}
}  // namespace

TEST_CASE("logger: a backend note joins the fault record of its cycle, or gets a record of its own",
          "[can_backend][log]") {
  namespace fl = manip::control::fault;
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("manip_notes_" + std::to_string(::getpid()) + ".lcm")).string();
  manip::runtime::RecordQueue q(64);
  manip::runtime::Logger logger(q, 4, 10.0);
  logger.set_print_faults(false);
  FakeTap tap;
  logger.set_backend_tap(&tap);
  std::string err;
  manip::session_t session{};
  REQUIRE(logger.open(path, session, err, true));
  // cycle 10: the backend noted "A"; the supervisor raised kBackend in the same cycle
  tap.notes.push_back({10, bs::kDriveFault, "can backend: A"});
  REQUIRE(q.try_push(state_at(9, 0)));
  manip::control::FaultRecord f;
  f.cycle = 10;
  f.new_flags = f.fault_flags = fl::kBackend;
  REQUIRE(q.try_push(f));
  REQUIRE(q.try_push(state_at(10, fl::kBackend)));
  logger.drain();
  // cycle 20: note "B" with no new supervisor bit (already latched): own record once cycle 21 is seen
  tap.notes.push_back({20, bs::kBackendError, "can backend: B"});
  REQUIRE(q.try_push(state_at(20, fl::kBackend)));
  logger.drain();
  const auto before_21 = logger.stats().backend_notes;
  REQUIRE(q.try_push(state_at(21, fl::kBackend)));
  logger.drain();
  const auto after_21 = logger.stats().backend_notes;
  // at shutdown (outside the loop): "C"
  tap.notes.push_back({-1, bs::kBackendError, "can backend: C"});
  REQUIRE(logger.close(err));
  CHECK(before_21 == 1);
  CHECK(after_21 == 2);

  std::vector<manip::fault_t> faults;
  {
    manip::logging::EventLogReader rd(path);
    manip::logging::RawEvent ev;
    while (rd.next(ev))
      if (ev.channel == manip::channels::kFault) {
        manip::fault_t m;
        const auto n = static_cast<int>(ev.data.size());
        REQUIRE(m.decode(ev.data.data(), 0, n) == n);
        faults.push_back(m);
      }
  }
  std::filesystem::remove(path);
  REQUIRE(faults.size() == 3);
  CHECK(faults[0].cycle == 10);
  CHECK(faults[0].reason.find("backend") == 0);
  CHECK(faults[0].reason.find("; can backend: A") != std::string::npos);
  CHECK(faults[0].n_history > 0);
  CHECK(faults[1].cycle == 20);
  CHECK(faults[1].reason == "can backend: B");
  CHECK(faults[1].fault_flags == static_cast<std::int32_t>(fl::kBackend));
  CHECK(faults[1].n_history == 0);
  CHECK(faults[2].cycle == -1);
  CHECK(faults[2].reason == "can backend: C");
}

TEST_CASE("can backend: the e-stop chain on digital input 0x60FD (TPDO2) is a latched hardware e-stop with its reason",
          "[can_backend][estop]") {
  const auto cfg = rt_cfg();
  auto can = can_cfg();
  can.backend.estop_input_bit = 16;          // the chain's contact on the drive's input 16 (manufacturer-specific)
  can.backend.estop_input_open_high = false;  // closed chain holds it high
  for (auto& d : can.drives) {  // TPDO2 carries 0x60FD instead of the velocity
    d.tpdo2 = cc::PdoMapping{};
    d.tpdo2.add(cc::PdoObject::DigitalInputs);
  }
  hw::CanBackend b(cfg, cfg.sim, can);
  started(b);
  CHECK(b.budget_text().find("TPDO2") != std::string::npos);
  CHECK(b.sim_drive(0)->od_value(0x1A01, 1) == 0x60FD0020u);  // mapped by the start-up SDO list
  Loop l{b};
  for (int i = 0; i < 400; ++i) l.cycle(Vec2(2.0, 2.0));
  REQUIRE(l.r.status == bs::kDrivesEnabled);  // closed chain: no e-stop
  b.sim_drive(1)->faults().digital_inputs &= ~(1u << 16);  // open the chain at the drive of axis 1
  const int n = l.until(bs::kHwEStopOpen, 4);  // next TPDO2: within 2 SYNC periods
  INFO(b.fault_reason());
  REQUIRE(n > 0);
  CHECK(b.fault_reason().find("e-stop chain open") != std::string::npos);
  CHECK(b.fault_reason().find("0x60FD") != std::string::npos);
  CHECK(b.fault_reason().find("axis 1") != std::string::npos);
  hw::BackendFaultNote note;
  REQUIRE(b.next_fault_note(note));
  CHECK(note.status == bs::kHwEStopOpen);
  CHECK(note.text.find("bit 16") != std::string::npos);
  for (int i = 0; i < 40; ++i) l.cycle();
  CHECK((l.r.status & bs::kHwEStopOpen) != 0);  // present while the chain is open
  b.sim_drive(1)->faults().digital_inputs |= 1u << 16;  // closed again
  for (int i = 0; i < 4; ++i) l.cycle();
  CHECK((l.r.status & bs::kHwEStopOpen) == 0);  // not present: the operator may reset
  CHECK_FALSE(b.fault_reason().empty());         // the reason stays latched until then
}

TEST_CASE("can backend: the whole loop (RtCycle, controller, CAN) stays allocation-free with raw recording, a drive "
          "fault and the operator's reset", "[can_backend][no_alloc][fault_reset]") {
  using manip::control::Mode;
  const auto cfg = rt_cfg();
  auto can = can_cfg();
  can.backend.record_raw_frames = true;  // default queue (65 536 frames), drained outside the counted region
  hw::CanBackend b(cfg, cfg.sim, can);
  started(b);
  SupervisedLoop s(cfg, b);
  s.run(2000);
  REQUIRE(s.mode() == Mode::kRunning);
  long news = 0;
  manip::can_frames_t batch;
  hw::BackendFaultNote note;
  std::int64_t frames = 0, notes = 0;
  auto counted = [&](int n) {
    {
      const manip::test::ThreadAllocScope scope;
      s.cycles(n);
      news += scope.counts().news;
    }
    s.drain();  // the logger's side allocates (messages, strings): not the loop
    while (b.next_raw_batch(batch, 4096)) frames += batch.n;
    while (b.next_fault_note(note)) ++notes;
  };
  for (int i = 0; i < 8; ++i) counted(256);
  b.sim_drive(0)->enter_fault(0x2310, 0);
  for (int i = 0; i < 8; ++i) counted(256);
  REQUIRE(s.mode() == Mode::kFault);
  s.command(manip::command_t::FAULT_RESET);
  for (int i = 0; i < 8; ++i) counted(256);
  REQUIRE(s.mode() == Mode::kPaused);
  REQUIRE((s.body.reading().status & bs::kDrivesEnabled) != 0);
  s.command(manip::command_t::RESUME);
  for (int i = 0; i < 8; ++i) counted(256);
  CHECK(s.mode() == Mode::kRunning);
  CHECK(news == 0);
  CHECK(notes >= 1);
  CHECK(frames > 4 * 8 * 256);  // ~4 frames per loop cycle on two buses
  CHECK(b.raw_frames_dropped() == 0);
}

TEST_CASE("docs/hardware.md: the Python example reads the raw CAN frames next to the session's states",
          "[can_backend][log][python]") {
  // The example is taken from the document itself, so the two cannot drift apart.
  std::ifstream doc(kSrc + "/docs/hardware.md");
  std::stringstream ds;
  ds << doc.rdbuf();
  const std::string text = ds.str();
  const auto anchor = text.find("Reading it next to the session's state in Python");
  REQUIRE(anchor != std::string::npos);
  const auto begin = text.find("```python\n", anchor);
  REQUIRE(begin != std::string::npos);
  const auto end = text.find("```", begin + 10);
  std::string code = text.substr(begin + 10, end - begin - 10);

  const auto base = rt_cfg();
  const auto cfg = manip::runtime::load_rt_config(kSrc + "/config/rt.yaml", manip::runtime::trials_overrides(base, 2));
  auto can = can_cfg();
  can.backend.record_raw_frames = true;
  hw::CanBackend b(cfg, cfg.sim, can);
  const std::string dir = std::filesystem::temp_directory_path() / ("manip_rawpy_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  auto opt = offline_run_options(dir + "/session.lcm");
  opt.duration_s = 0.25;
  std::ostringstream out;
  const auto rep = manip::runtime::run_session(cfg, b, opt, out);
  REQUIRE(rep.exit_code == 0);
  REQUIRE(rep.log.raw_frames > 0);

  auto replace = [&](const std::string& from, const std::string& to) {
    const auto at = code.find(from);
    REQUIRE(at != std::string::npos);
    code.replace(at, from.size(), to);
  };
  replace("\"build/python\"", "\"" + std::string(MANIP_BINARY_DIR) + "/python\"");
  replace("\"session.lcm\"", "\"" + dir + "/session.lcm\"");
  {
    std::ofstream py(dir + "/example.py");
    py << code;
  }
  const std::string python = MANIP_PYTHON;
  REQUIRE(std::filesystem::exists(python));
  std::string printed;
  const int rc = manip::testutil::run_command(python + " " + dir + "/example.py", &printed);
  std::filesystem::remove_all(dir);
  INFO(printed.substr(0, 2000));
  REQUIRE(rc == 0);
  std::istringstream lines(printed);
  std::string line;
  std::int64_t n = 0, sync_tx = 0, with_state = 0;
  while (std::getline(lines, line)) {
    ++n;
    sync_tx += line.find(" TX 080#  x = (") != std::string::npos;  // in the loop (a state of the cycle)
    with_state += line.find("x = (") != std::string::npos;
  }
  CHECK(n == rep.log.raw_frames);           // one candump-like line per logged frame
  CHECK(std::abs(sync_tx - rep.cycles) <= 4);  // the SYNC of every drive tick (every 2nd cycle) on both buses
  CHECK(with_state > n / 2);                // the loop's frames sit next to their state
}
