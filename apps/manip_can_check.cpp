// manip_can_check: commissioning check of the CANopen bus (docs/hardware.md).
#include <CLI/CLI.hpp>

#include <chrono>
#include <iostream>
#include <thread>

#include "manip/canopen/can_check.hpp"
#include "manip/common/cli.hpp"
#include "manip/common/errors.hpp"
#include "manip/version.hpp"
#include "manip/canopen/socketcan.hpp"

namespace {
namespace ec = manip::exit_code;
// The one table (common/exit_codes.hpp): the check's own verdicts (can_check.hpp)
// mapped onto it. A budget above master.max_bus_load is a configuration this bus
// cannot run; a silent or misconfigured drive and a missing interface are the
// hardware backend failing to come up, as manip_rt --backend can would report it.
const std::vector<int> kExitCodes = {ec::kOk, ec::kUsage, ec::kConfig, ec::kBackend, ec::kInternal};
int to_exit_code(int check) {
  switch (check) {
    case manip::canopen::kCheckOk: return ec::kOk;
    case manip::canopen::kCheckConfig: return ec::kConfig;
    case manip::canopen::kCheckBudget: return ec::kConfig;
    case manip::canopen::kCheckDrive: return ec::kBackend;
    case manip::canopen::kCheckInterface: return ec::kBackend;
    default: return ec::kInternal;
  }
}
}  // namespace

int run(int argc, char** argv) {
  using namespace manip::canopen;
  namespace cli = manip::cli;
  CLI::App app{"manip_can_check " + std::string(manip::kVersion) +
                   ": scan the configured CANopen bus, read identities, write and verify the start-up "
                   "configuration, measure PDO rates, print the bus budget",
               "manip_can_check"};
  app.footer(
      "Verdicts: 0 every drive answered, configuration written and verified, PDO rates achieved; 3 the bus file is "
      "invalid or its worst-case bus load is above master.max_bus_load; 8 a drive or the bus would stop a session, or "
      "the CAN interface is unavailable (reason printed).");
  cli::Common c;
  bool virt = false;
  std::string fault = "none";
  int periods = 2000;
  cli::add_version(app, "manip_can_check");
  cli::add_quiet(app, c.quiet);
  cli::add_config(app, c.config, "can.yaml", "bus configuration YAML");
  app.add_flag("--virtual", virt, "run simulated drives in-process on a virtual bus instead of SocketCAN");
  const std::vector<std::string> faults = {"none", "never-boot", "sdo-silent", "wrong-node", "tpdo-loss"};
  app.add_option("--virtual-fault", fault, "with --virtual: " + cli::join(faults))
      ->check(cli::one_of(faults))
      ->capture_default_str();
  app.add_option("--periods", periods, "SYNC periods of cyclic operation to measure")->check(CLI::Range(1, 4000000))
      ->capture_default_str();
  cli::set_exit_codes(app, kExitCodes);
  if (const auto rc = cli::parse(app, argc, argv)) return *rc;
  const std::string config = cli::find_config(c.config, "can.yaml");

  CanConfig cfg;
  std::vector<std::string> errors;
  if (!load_config(config, cfg, errors)) {
    for (const auto& e : errors) std::cerr << e << "\n";
    return to_exit_code(kCheckConfig);
  }
  CheckResult r;
  if (virt) {
    VirtualRig rig(cfg);
    if (fault == "never-boot") rig.drive(0).faults().never_boot = true;
    if (fault == "sdo-silent") rig.drive(0).faults().sdo_silent = true;
    if (fault == "wrong-node") rig.drive(0).faults().answer_as_node = static_cast<uint8_t>(rig.drive(0).node_id() % 127 + 1);
    if (fault == "tpdo-loss") rig.drive(0).faults().drop_tpdos = static_cast<uint32_t>(periods / 20 + 10);
    r = run_can_check(cfg, rig.master_ports(), [&] { return rig.tick(); }, periods);
  } else {
    std::vector<std::unique_ptr<SocketCanPort>> owned;
    std::vector<CanPort*> ports;
    for (const auto& b : cfg.buses) {
      std::string err;
      auto p = SocketCanPort::open(b.interface, master_filters(), err);
      if (!p) {
        std::cerr << "manip_can_check: bus " << b.name << ": " << err << "\n";
        return to_exit_code(kCheckInterface);
      }
      ports.push_back(p.get());
      owned.push_back(std::move(p));
    }
    using clock = std::chrono::steady_clock;
    const auto t0 = clock::now();
    auto next = t0;
    // 4 kHz like manip_rt; commissioning does not need real-time scheduling.
    r = run_can_check(cfg, ports, [&] {
      next += std::chrono::microseconds(250);
      std::this_thread::sleep_until(next);
      return std::chrono::duration_cast<std::chrono::microseconds>(clock::now() - t0).count();
    }, periods);
  }
  if (!c.quiet || r.exit_code != kCheckOk) std::cout << r.report;
  return to_exit_code(r.exit_code);
}

int main(int argc, char** argv) { return manip::cli::run_main("manip_can_check", run, argc, argv); }
