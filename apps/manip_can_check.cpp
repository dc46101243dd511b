// manip_can_check: commissioning check of the CANopen bus (docs/hardware.md).
#include <CLI/CLI.hpp>

#include <chrono>
#include <iostream>
#include <thread>

#include "manip/canopen/can_check.hpp"
#include "manip/canopen/socketcan.hpp"

namespace {
const char* kExitCodes =
    "Exit codes:\n"
    "  0  every drive answered, configuration written and verified, PDO rates achieved\n"
    "  1  configuration invalid (file:line: key: reason)\n"
    "  2  worst-case bus load above master.max_bus_load\n"
    "  3  a drive or the bus would stop a session (reason printed)\n"
    "  4  CAN interface unavailable\n";
}

int main(int argc, char** argv) {
  using namespace manip::canopen;
  CLI::App app{"manip_can_check: scan the configured CANopen bus, read identities, write and verify the "
               "start-up configuration, measure PDO rates, print the bus budget"};
  app.footer(kExitCodes);
  std::string config;
  bool virt = false;
  std::string fault = "none";
  int periods = 2000;
  app.add_option("--config", config, "bus configuration YAML")->required();
  app.add_flag("--virtual", virt, "run simulated drives in-process on a virtual bus instead of SocketCAN");
  app.add_option("--virtual-fault", fault, "with --virtual: none | never-boot | sdo-silent | wrong-node | tpdo-loss")
      ->check(CLI::IsMember({"none", "never-boot", "sdo-silent", "wrong-node", "tpdo-loss"}))
      ->capture_default_str();
  app.add_option("--periods", periods, "SYNC periods of cyclic operation to measure")->check(CLI::PositiveNumber)
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  CanConfig cfg;
  std::vector<std::string> errors;
  if (!load_config(config, cfg, errors)) {
    for (const auto& e : errors) std::cerr << e << "\n";
    return kCheckConfig;
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
        return kCheckInterface;
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
  std::cout << r.report;
  return r.exit_code;
}
