// --require-rt enforced inside the loop thread (libfranka's kEnforce): when the
// thread itself cannot get SCHED_FIFO/mlock, the run ends before its first
// cycle with exit code 9, and the log, the bus and the drives are never
// touched. The real-time environment is injected (RunOptions::rt), so this
// runs without root and on any kernel.
#include <catch2/catch.hpp>

#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <sstream>
#include <string>
#include <thread>

#include "manip/common/exit_codes.hpp"
#include "manip/hardware/backend.hpp"
#include "manip/runtime/config.hpp"
#include "manip/runtime/session.hpp"

using namespace manip::runtime;
namespace hw = manip::hardware;

namespace {

// Holds a handle at rest (valid readings, fresh every cycle).
class CountingBackend final : public hw::Backend {
 public:
  std::atomic<long> reads{0}, writes{0};
  int configures{0}, enables{0};
  [[nodiscard]] std::string name() const override { return "counting"; }
  void read(manip::control::SensorReading& r) override {
    const auto n = static_cast<std::uint64_t>(reads.fetch_add(1) + 1);
    r = {};
    r.x_workspace_m = manip::Vec2(0.0, 0.30 - 0.425);  // in the start target
    r.position_seq = r.force_seq = n;
    r.status = manip::control::backend_status::kDrivesEnabled;
  }
  void write(const manip::control::ActuatorCommand&) override { writes.fetch_add(1); }

 protected:
  void on_configure() override { ++configures; }
  void on_enable() override { ++enables; }
  void on_disable() noexcept override {}
};

RtCapabilities all_granted() {
  RtCapabilities c;
  c.preempt_rt = true;
  c.is_root = true;
  c.rtprio_limit = 99;
  c.kernel_release = "test";
  return c;
}

std::atomic<std::thread::id> g_setup_thread{};
bool setup_fails(const RtThreadOptions&, std::string& err) {
  g_setup_thread.store(std::this_thread::get_id());
  err = "cannot set SCHED_FIFO priority 80 (Operation not permitted)";
  return false;
}

std::string tmp_log(const char* name) {
  return (std::filesystem::temp_directory_path() /
          (std::string("manip_rt_enforce_") + name + "_" + std::to_string(::getpid()) + ".lcm"))
      .string();
}

}  // namespace

TEST_CASE("require-rt: a loop thread that cannot get SCHED_FIFO/mlock never cycles, exit 9", "[realtime][session]") {
  const RtConfig cfg;
  CountingBackend backend;
  RunOptions opt;
  opt.realtime = true;
  opt.require_rt = true;
  opt.duration_s = 0.05;
  opt.lcm_url = "none";
  opt.quiet = true;
  opt.log_path = tmp_log("refused");
  std::filesystem::remove(opt.log_path);
  opt.rt.detect = &all_granted;  // the up-front check passes ...
  opt.rt.setup_thread = &setup_fails;  // ... but the thread's own set-up fails
  g_setup_thread.store(std::thread::id{});
  std::ostringstream out;
  const RunReport rep = run_session(cfg, backend, opt, out);
  INFO(rep.message);
  CHECK(rep.exit_code == manip::exit_code::kRealtime);
  CHECK(rep.exit_code == 9);
  CHECK(rep.cycles == 0);
  CHECK(backend.reads.load() == 0);
  CHECK(backend.writes.load() == 0);
  CHECK(backend.configures == 0);  // the drives were never opened
  CHECK(backend.state() == hw::BackendState::kFinalized);
  CHECK_FALSE(std::filesystem::exists(opt.log_path));  // no log of a run that never ran
  CHECK(rep.message.find("SCHED_FIFO") != std::string::npos);
  CHECK(rep.message.find("no cycle was run") != std::string::npos);
  // the set-up ran in the loop thread, not in the caller's
  CHECK(g_setup_thread.load() != std::thread::id{});
  CHECK(g_setup_thread.load() != std::this_thread::get_id());
}

TEST_CASE("without --require-rt a failed thread set-up is a warning and the run goes on", "[realtime][session]") {
  RtConfig cfg;
  // Without SCHED_FIFO on a loaded CI machine overruns may latch a fault,
  // which (correctly) makes the run exit 7; this test is about the warning.
  cfg.cycle.overrun_fault_consecutive = 100000;
  cfg.cycle.overrun_fault_per_second = 100000;
  CountingBackend backend;
  RunOptions opt;
  opt.realtime = true;
  opt.duration_s = 0.05;
  opt.lcm_url = "none";
  opt.quiet = true;
  opt.rt.detect = &all_granted;
  opt.rt.setup_thread = &setup_fails;
  std::ostringstream out;
  const RunReport rep = run_session(cfg, backend, opt, out);
  INFO(out.str() << rep.message);
  CHECK(rep.exit_code == manip::exit_code::kOk);
  CHECK(rep.cycles == 200 + cfg.safety.shutdown_cycles);  // 0.05 s at 4 kHz, then the orderly stop
  CHECK(backend.reads.load() == rep.cycles);
  CHECK(backend.configures == 1);
  CHECK(backend.enables == 1);
  CHECK(backend.state() == hw::BackendState::kFinalized);
  CHECK(out.str().find("warning: cannot set SCHED_FIFO") != std::string::npos);
}
