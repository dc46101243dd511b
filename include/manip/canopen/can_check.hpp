#pragma once
// Commissioning check (`manip_can_check`) and the in-process virtual set-up
// it and the tests use (`--virtual`: one VirtualBus per configured bus, one
// SimulatedDrive per configured drive, parameters taken from the config).
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "manip/canopen/drive_set.hpp"
#include "manip/canopen/simulated_drive.hpp"
#include "manip/canopen/virtual_bus.hpp"

namespace manip::canopen {

SimDriveParams sim_params_for(const DriveConfig& d);

class VirtualRig {
 public:
  // tweak: adjust each simulated drive's parameters (mass, friction, ...).
  explicit VirtualRig(const CanConfig& cfg, int64_t step_us = 250,
                      const std::function<void(SimDriveParams&)>& tweak = {});
  // Advance simulated time by one control period, run every simulated drive.
  int64_t tick();
  int64_t now() const { return now_us_; }
  std::vector<CanPort*> master_ports();
  std::size_t drive_count() const { return drives_.size(); }
  SimulatedDrive& drive(std::size_t i) { return *drives_[i]; }
  SimulatedDrive* drive_by_node(const std::string& bus, uint8_t node);
  VirtualBus& bus(std::size_t i) { return *buses_[i]; }
  std::size_t bus_count() const { return buses_.size(); }
  // Add a drive not in the config (e.g. an unexpected node) on bus i.
  SimulatedDrive& add_drive(std::size_t bus, const SimDriveParams& p);

 private:
  int64_t now_us_ = 0;
  int64_t step_us_;
  std::vector<std::unique_ptr<VirtualBus>> buses_;
  std::vector<VirtualBus::Endpoint*> master_eps_;
  std::vector<std::unique_ptr<SimulatedDrive>> drives_;
  std::vector<VirtualBus::Endpoint*> drive_eps_;
  std::vector<std::string> drive_bus_;
};

// Exit codes of manip_can_check.
enum CheckExit : int { kCheckOk = 0, kCheckConfig = 1, kCheckBudget = 2, kCheckDrive = 3, kCheckInterface = 4 };

struct CheckResult {
  int exit_code = kCheckOk;
  std::string report;  // human-readable, printed by the program
};

// Budget, start-up (identity, device type, error register, rated current,
// heartbeat and PDO settings written and read back), `sync_periods` of cyclic
// operation checking that every configured TPDO arrives at the SYNC rate,
// then shutdown.
CheckResult run_can_check(const CanConfig& cfg, const std::vector<CanPort*>& ports, const CanDriveSet::Ticker& tick,
                          int sync_periods = 400);

}  // namespace manip::canopen
