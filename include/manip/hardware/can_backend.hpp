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
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "manip/canopen/can_check.hpp"
#include "manip/canopen/drive_set.hpp"
#include "manip/canopen/frame_recorder.hpp"
#include "manip/canopen/socketcan.hpp"
#include "manip/common/spsc_queue.hpp"
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

// Operator fault reset (request_fault_reset(), called when the supervisor
// accepts FAULT_RESET): what a lab expects from libfranka's
// automaticErrorRecovery or ros2_canopen's `recover` service. A CANopen fault
// the drives can recover from (CiA 402 Fault, a faulting EMCY, missing
// TPDOs) raises its status bit in the detecting cycle only: the supervisor
// latches it, and the master itself keeps the drives disabled at zero torque
// until the reset, so the fault is "latched, acknowledgeable" rather than
// "present". The reset sends one rising edge of 0x6040 bit 7 per drive in
// Fault (CiA 402 transition 15 -> Switch on disabled), then re-enables the
// drives through transitions 2, 3, 4 with zero target torque preloaded; the
// session goes on in the supervisor's PAUSED mode (hold: admittance, no
// trials) until the operator resumes. A drive still in Fault
// master.fault_reset_timeout_ms after the edge, or not back in Operation enabled in time, raises
// the fault again (with its reason) and cancels the enable walk.
// E-stop / STO: a drive leaving Operation enabled without the master's
// command (0x6041 bit 4 off, Switch on disabled, Ready to switch on, Quick
// stop active, ...) faults its bus (canopen::ErrorCode::UncommandedDisable),
// and an e-stop chain read open (statusword bit, 0x60FD input) stops the whole
// set (ErrorCode::EStopChain): both drives stay disabled when the power
// returns; only the operator's reset re-enables them, and the supervisor
// refuses it while the chain reads open (docs/hardware.md "Fault policy"). Faults that lose the drives'
// configuration or the bus (heartbeat loss, reboot, bus-off, unexpected
// node, refused sends) stay present: the reset is refused ("condition
// present") and only a restart of manip_rt re-initialises the bus.
class CanBackend final : public Backend, public BackendLogTap {
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
  void request_fault_reset() noexcept override;
  BackendLogTap* log_tap() noexcept override { return this; }
  // BackendLogTap (logger thread): fault notes (the decoded CANopen reason,
  // e-stop, sensor) and, with backend.record_raw_frames, the raw traffic.
  bool next_fault_note(BackendFaultNote& out) override;
  bool next_raw_batch(manip::can_frames_t& out, std::size_t max_frames) override;
  // Frames lost because the raw-frame queue was full (0 when not recording).
  [[nodiscard]] std::int64_t raw_frames_dropped() const { return recorder_ ? recorder_->dropped() : 0; }
  [[nodiscard]] const canopen::FrameRecorder* recorder() const { return recorder_.get(); }
  // Fault notes the loop could not queue (more than kNotes unread).
  [[nodiscard]] std::int64_t fault_notes_dropped() const { return notes_dropped_.load(std::memory_order_relaxed); }

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

  enum class Latch : std::uint8_t { kNone, kCanopen, kEStop, kSensorStale, kEventStatus };
  // A fault as the loop records it (plain value); formatted by describe().
  struct Note {
    std::int64_t cycle{-1};
    std::uint32_t status{0};
    Latch kind{Latch::kNone};
    canopen::Error error{};
    int axis{-1};
    std::uint16_t statusword{0};
    bool by_input{false};     // e-stop from 0x60FD (else statusword / voltage)
    // kEventStatus: error.node and error.value = Copley's 0x1002 read at shutdown
    std::uint32_t inputs{0};  // 0x60FD
  };
  static constexpr std::size_t kNotes = 32;
  std::string describe(const Note& n) const;
  void note(const Note& n) noexcept;
  enum class Reset : std::uint8_t { kNone, kClearing, kEnabling };

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
  std::int64_t cycles_{0};
  std::int64_t last_write_us_{0};
  Vec2 last_force_n_{Vec2::Zero()};
  std::uint32_t last_status_{0};
  Latch latch_{Latch::kNone};
  canopen::Error latched_error_{};
  int estop_axis_{-1};
  std::uint16_t estop_statusword_{0};
  bool estop_by_input_{false};
  std::uint32_t estop_inputs_{0};
  std::string budget_text_;
  // operator fault reset and fault notes
  std::int64_t loop_cycle_{-1};  // cycle of the current read() (-1 outside the loop)
  bool fault_seen_{false};       // the current CANopen fault episode has raised its bit
  bool estop_open_{false};       // chain open in the last read()
  bool stale_{false};            // force sensor stale in the last read()
  Reset reset_{Reset::kNone};
  std::int64_t reset_deadline_us_{0};
  std::uint32_t resets_failed_seen_{0};
  SpscQueue<Note> notes_{kNotes};
  std::atomic<std::int64_t> notes_dropped_{0};
  std::unique_ptr<canopen::FrameRecorder> recorder_;
};

}  // namespace manip::hardware
