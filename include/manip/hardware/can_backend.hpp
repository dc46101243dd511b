#pragma once
// The `can` backend: the two stages' CiA 402 drives over CANopen
// (canopen::CanDriveSet, one passive Master per bus) and the handle force
// sensor (force_sensor.hpp), behind the hardware boundary (backend.hpp).
//
//   configure(): bus budget (refused above master.max_bus_load, with the
//     budget table in the error), SocketCAN ports (or the in-process virtual
//     rig), NMT reset, SDO start-up in pre-operational (identity, heartbeat
//     consumer 0x1016 / producer 0x1017, PDO mapping written and read back,
//     mode 10 CST), NMT start; drives stay disabled; force sensor started.
//   enable(): CiA 402 to Operation enabled with zero target torque preloaded;
//     the force bias (tare) restarts.
//   read(): one control cycle: SYNC clock = the loop's own cycle (cycle
//     count x loop period in --can-virtual, CLOCK_MONOTONIC otherwise);
//     received frames -> positions/velocities (counts -> workspace metres,
//     sign and axis from config), force sensor, status bits (drive fault,
//     e-stop/STO, communication error).
//   write(): forces -> 0x6071 target torque per mille at the drive rate (the
//     controller sends at drive ticks); SYNC + RPDO go out in the same call.
//     command.enable == false only zeroes the torque: the CiA 402 state
//     follows the lifecycle (disable()).
//   disable(): Disable voltage, wait until no drive is Operation enabled.
//   shutdown(): disable, NMT pre-operational/stop as the master documents,
//     ports closed; the first fault's reason is printed (stderr).
//
// --can-virtual (backend.virtual: true): the configured drives run as
// canopen::SimulatedDrive on a VirtualBus in the same process, in simulated
// time; the stages and the person holding the handle are the sim backend's
// plant (SimBackend: stage masses and friction of rt.yaml `sim:`, the
// simulated person of sim.human, the simulated force sensor, used whatever
// backend.force_sensor says), driven by the
// force each simulated drive applies from its CAN target torque.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "manip/canopen/can_check.hpp"
#include "manip/canopen/drive_set.hpp"
#include "manip/canopen/socketcan.hpp"
#include "manip/control/config.hpp"
#include "manip/hardware/backend.hpp"
#include "manip/hardware/force_sensor.hpp"
#include "manip/hardware/sim_backend.hpp"

namespace manip::hardware {

struct CanBackendOptions {
  std::string config_path{"config/can.yaml"};
  bool force_virtual{false};  // --can-virtual
};

// Reads and validates the CANopen file (ConfigError "file:line: key: reason").
canopen::CanConfig load_can_config(const std::string& path);

class CanBackend final : public Backend {
 public:
  // sensor: overrides the configured force source (tests); nullptr = from config.
  CanBackend(const control::ControlConfig& law, const SimConfig& sim, const canopen::CanConfig& can,
             std::unique_ptr<ForceSource> sensor = nullptr);
  ~CanBackend() override;

  [[nodiscard]] std::string name() const override { return "can"; }
  [[nodiscard]] bool supports_as_fast_as_possible() const override { return virtual_; }
  void read(control::SensorReading& out) override;
  void write(const control::ActuatorCommand& cmd) override;
  void display(const control::DisplayCue& cue) override;

  // --can-virtual: called with the rig after it is built, before the SDO
  // start-up (tests inject start-up faults into the simulated drives here).
  std::function<void(canopen::VirtualRig&)> before_startup;

  [[nodiscard]] bool is_virtual() const { return virtual_; }
  [[nodiscard]] canopen::CanDriveSet& drives() { return *set_; }
  // --can-virtual only (nullptr otherwise).
  [[nodiscard]] canopen::VirtualRig* rig() { return rig_.get(); }
  [[nodiscard]] SimBackend* plant() { return plant_.get(); }
  [[nodiscard]] canopen::SimulatedDrive* sim_drive(int axis) { return axis_drive_[std::size_t(axis)]; }
  [[nodiscard]] const ForceBoundary& force() const { return force_; }
  [[nodiscard]] std::int64_t now_us() const { return now_us_; }
  [[nodiscard]] std::int64_t cycles() const { return cycles_; }
  // The latched reason of the first fault (CANopen error text, e-stop, sensor); "" if none.
  [[nodiscard]] std::string fault_reason() const;
  // backend_status bits raised by the last read().
  [[nodiscard]] std::uint32_t last_status() const { return last_status_; }
  // Budget tables printed at configure().
  [[nodiscard]] const std::string& budget_text() const { return budget_text_; }

 private:
  void on_configure() override;
  void on_enable() override;
  void on_disable() noexcept override;
  void on_shutdown() noexcept override;
  std::int64_t tick();  // lifecycle ticker: one loop period
  std::int64_t clock_us() const;
  void step_virtual_plant();
  [[noreturn]] void fail(const std::string& what, const canopen::Error& e);

  enum class Latch : std::uint8_t { kNone, kCanopen, kEStop, kSensorStale };

  control::ControlConfig law_;
  SimConfig sim_;
  canopen::CanConfig can_;
  bool virtual_;
  std::int64_t period_us_;
  std::unique_ptr<ForceSource> sensor_;
  ForceBoundary force_;
  // virtual set-up
  std::unique_ptr<canopen::VirtualRig> rig_;
  std::unique_ptr<SimBackend> plant_;
  std::array<canopen::SimulatedDrive*, 2> axis_drive_{nullptr, nullptr};
  std::array<int, 2> axis_sign_{1, 1};
  Vec2 plant_force_n_{Vec2::Zero()};
  control::SensorReading plant_reading_{};
  bool plant_started_{false};
  // SocketCAN
  std::vector<std::unique_ptr<canopen::SocketCanPort>> ports_;
  std::unique_ptr<canopen::CanDriveSet> set_;
  std::int64_t now_us_{0};
  std::int64_t t0_us_{0};
  std::int64_t cycles_{0};
  std::int64_t last_write_us_{0};
  Vec2 last_force_n_{Vec2::Zero()};
  std::uint32_t last_status_{0};
  Latch latch_{Latch::kNone};
  canopen::Error latched_error_{};
  int estop_axis_{-1};
  std::uint16_t estop_statusword_{0};
  std::string budget_text_;
};

}  // namespace manip::hardware
