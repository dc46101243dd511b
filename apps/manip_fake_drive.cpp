// manip_fake_drive: a simulated CiA 402 drive on a SocketCAN interface (the
// same SimulatedDrive the tests use on the virtual bus), for testing manip_rt
// --backend can and manip_can_check without hardware, e.g. on vcan0.
#include <CLI/CLI.hpp>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <cstdio>
#include <iostream>
#include <thread>

#include "manip/canopen/simulated_drive.hpp"
#include "manip/common/cli.hpp"
#include "manip/common/errors.hpp"
#include "manip/version.hpp"
#include "manip/canopen/socketcan.hpp"

namespace {
std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop.store(true); }

namespace ec = manip::exit_code;
// Stopped by SIGINT/SIGTERM is this tool's normal end (it runs until told), hence 0, not 130.
const std::vector<int> kExitCodes = {ec::kOk, ec::kUsage, ec::kBackend, ec::kInternal};

int run(int argc, char** argv) {
  using namespace manip::canopen;
  namespace cli = manip::cli;
  CLI::App app{"manip_fake_drive " + std::string(manip::kVersion) +
                   ": simulated CiA 402 drive (CST, moving mass with friction) on SocketCAN; runs until SIGINT/SIGTERM "
                   "or --duration (exit 0); 8 = the CAN interface is unavailable",
               "manip_fake_drive"};
  std::string iface = "vcan0";
  int node = 1;
  SimDriveParams p;
  double duration_s = 0;
  bool never_boot = false, sdo_silent = false, quiet = false;
  int answer_as = 0, drop_tpdos = 0;
  long long delay_tpdo_us = 0;
  double stop_heartbeat_after_s = -1, fault_after_s = -1;
  std::string reject;
  const double kHuge = 1e12;  // bounds only to refuse nonsense (and nan/inf); physical sense is the user's
  cli::add_version(app, "manip_fake_drive");
  cli::add_quiet(app, quiet)->description("no 1 Hz status line on stdout");
  app.add_option("--iface", iface, "CAN interface")->capture_default_str();
  app.add_option("--node", node, "node id 1..127")->check(CLI::Range(1, 127))->capture_default_str();
  app.add_option("--mass-kg", p.mass_kg, "moving mass [kg]")->check(cli::finite_range(1e-6, kHuge))->capture_default_str();
  app.add_option("--viscous-nspm", p.viscous_nspm, "viscous friction [N s/m]")->check(cli::finite_range(0, kHuge))
      ->capture_default_str();
  app.add_option("--coulomb-n", p.coulomb_n, "Coulomb friction [N]")->check(cli::finite_range(0, kHuge))->capture_default_str();
  app.add_option("--counts-per-m", p.counts_per_m, "encoder counts per metre")->check(cli::finite_range(1, kHuge))
      ->capture_default_str();
  app.add_option("--rated-current-a", p.rated_current_a, "0x6075 [A]")->check(cli::finite_range(1e-6, kHuge))
      ->capture_default_str();
  app.add_option("--force-constant-n-per-a", p.force_constant_n_per_a, "motor force constant [N/A]")
      ->check(cli::finite_range(1e-9, kHuge))->capture_default_str();
  app.add_option("--sync-loss-limit", p.sync_loss_limit, "fault after N missed SYNC periods (0 = off)")
      ->check(CLI::NonNegativeNumber)->capture_default_str();
  app.add_option("--duration", duration_s, "stop after this many seconds (0 = until SIGINT)")
      ->check(cli::finite_range(0, kHuge));
  app.add_flag("--never-boot", never_boot, "fault injection: stay silent (no boot-up)");
  app.add_flag("--sdo-silent", sdo_silent, "fault injection: never answer SDOs");
  app.add_option("--answer-as-node", answer_as, "fault injection: answer SDOs with this node id")->check(CLI::Range(0, 127));
  app.add_option("--drop-tpdos", drop_tpdos, "fault injection: drop the first N TPDOs")->check(CLI::NonNegativeNumber);
  app.add_option("--delay-tpdo-us", delay_tpdo_us, "fault injection: send every TPDO this much later [us]")
      ->check(CLI::Range(0LL, 60000000LL));
  app.add_option("--stop-heartbeat-after", stop_heartbeat_after_s, "fault injection: stop the heartbeat after S s")
      ->check(cli::finite_range(-1, kHuge));
  app.add_option("--fault-after", fault_after_s, "fault injection: enter Fault (EMCY 0x2310) after S s")
      ->check(cli::finite_range(-1, kHuge));
  app.add_option("--reject-sdo", reject, "fault injection: INDEX:SUB:ABORT, e.g. 0x6060:0:0x06090030");
  cli::set_exit_codes(app, kExitCodes);
  if (const auto rc = cli::parse(app, argc, argv)) return *rc;

  p.node_id = static_cast<uint8_t>(node);
  SimulatedDrive drive(p);
  drive.faults().never_boot = never_boot;
  drive.faults().sdo_silent = sdo_silent;
  drive.faults().answer_as_node = static_cast<uint8_t>(answer_as);
  drive.faults().drop_tpdos = static_cast<uint32_t>(drop_tpdos);
  drive.faults().tpdo_delay_us = delay_tpdo_us;
  if (!reject.empty()) {
    // INDEX:SUB:ABORT, each decimal or 0x-hex.
    char* end = nullptr;
    const unsigned long idx = std::strtoul(reject.c_str(), &end, 0);
    const unsigned long sub = (*end == ':') ? std::strtoul(end + 1, &end, 0) : 0x10000;
    const unsigned long code = (*end == ':') ? std::strtoul(end + 1, &end, 0) : 0;
    if (*end != '\0' || idx > 0xFFFF || sub > 0xFF || code == 0 || code > 0xFFFFFFFFul) {
      throw manip::UsageError("--reject-sdo: expected INDEX:SUB:ABORT, e.g. 0x6060:0:0x06090030 (got " + reject + ")");
    }
    drive.faults().reject_index = static_cast<uint16_t>(idx);
    drive.faults().reject_sub = static_cast<uint8_t>(sub);
    drive.faults().reject_abort = static_cast<uint32_t>(code);
  }
  std::string err;
  auto port = SocketCanPort::open(iface, drive_filters(p.node_id), err);
  if (!port) {
    std::cerr << "manip_fake_drive: " << iface << ": " << err << "\n";
    return ec::kBackend;
  }
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  using clock = std::chrono::steady_clock;
  const auto t0 = clock::now();
  auto next = t0;
  int64_t last_print = 0;
  bool faulted = false;
  while (!g_stop.load()) {
    next += std::chrono::microseconds(250);
    std::this_thread::sleep_until(next);
    const int64_t now = std::chrono::duration_cast<std::chrono::microseconds>(clock::now() - t0).count();
    if (stop_heartbeat_after_s >= 0 && now >= stop_heartbeat_after_s * 1e6) drive.faults().heartbeat_stopped = true;
    if (fault_after_s >= 0 && !faulted && now >= fault_after_s * 1e6) {
      drive.enter_fault(0x2310, 1u);
      faulted = true;
    }
    drive.poll(now, *port);
    if (!quiet && now - last_print >= 1000000) {
      last_print = now;
      std::printf("node %d: NMT %s, %s, position %.6f m, velocity %.4f m/s, force %.2f N, %u SYNC\n", node,
                  to_string(drive.nmt_state()), cia402::to_string(drive.state()), drive.position_m(),
                  drive.velocity_mps(), drive.applied_force_n(), drive.sync_count());
      std::fflush(stdout);
    }
    if (duration_s > 0 && now >= duration_s * 1e6) break;
  }
  return ec::kOk;
}
}  // namespace

int main(int argc, char** argv) { return manip::cli::run_main("manip_fake_drive", run, argc, argv); }
