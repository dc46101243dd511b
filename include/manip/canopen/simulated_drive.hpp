#pragma once
// A simulated CiA 402 slave speaking the same frames as the real drives:
// NMT, SDO server over an object dictionary (expedited + segmented), PDOs
// with remapping, SYNC-driven cyclic synchronous torque (mode 10) acting on a
// moving mass with viscous and Coulomb friction, heartbeat producer and
// consumer (0x1016/0x1017), EMCY, and fault injection. Used by the unit tests
// over the VirtualBus, by `manip_can_check --virtual`, and by the
// `manip_fake_drive` program over SocketCAN. Passive like the Master.
#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "manip/canopen/cia402.hpp"
#include "manip/canopen/frame.hpp"

namespace manip::canopen {

struct SimDriveParams {
  uint8_t node_id = 1;
  double mass_kg = 2.0;               // moving mass of the stage
  double viscous_nspm = 2.0;
  double coulomb_n = 0.5;
  double counts_per_m = 1.0e6;        // encoder resolution
  double velocity_units_per_count_s = 1.0;
  double rated_current_a = 5.0;       // 0x6075 (stored in mA)
  double force_constant_n_per_a = 20.0;
  double initial_position_m = 0.0;
  uint32_t device_type = 0x00020192;  // 0x1000: CiA 402 (0x0192), servo drive
  uint32_t vendor_id = 0x000000AB;    // 0x1018:01 (Copley Controls' CiA vendor id)
  uint32_t product_code = 0x00001234;
  uint32_t revision = 0x00010000;
  uint32_t serial = 0x00C0FFEE;
  std::string device_name = "manip simulated CiA 402 drive";  // 0x1008 (segmented upload)
  uint32_t sync_loss_limit = 2;       // fault after this many missed SYNC periods (Copley-like)
  int64_t boot_delay_us = 20000;      // power-on / reset node to boot-up message
  bool has_event_status = true;       // Copley 0x1002 manufacturer status register
  // The stage is simulated outside the drive (the `can --can-virtual` backend
  // couples both stages to a simulated person): the drive only turns its
  // target torque into applied_force_n() and reports the position/velocity
  // given by set_plant_state() in 0x6064/0x606C.
  bool external_plant = false;
};

struct SimFaults {
  bool never_boot = false;          // no boot-up, no heartbeat, no answers
  bool heartbeat_stopped = false;   // stop the heartbeat producer
  uint32_t drop_tpdos = 0;          // drop the next N TPDOs
  bool drop_all_tpdos = false;
  int64_t tpdo_delay_us = 0;        // hold every TPDO this long before sending it
  bool sdo_silent = false;          // never answer SDOs (-> SDO timeout)
  uint16_t reject_index = 0;        // abort SDOs to this object...
  uint8_t reject_sub = 0;
  uint32_t reject_abort = 0;        // ...with this abort code
  uint8_t answer_as_node = 0;       // answer SDOs with this node id (0 = own id)
  uint16_t statusword_extra = 0;    // bits ORed into 0x6041 (e.g. a manufacturer-specific STO bit)
  bool fault_persists = false;      // the fault's cause stays (e.g. over-temperature): a reset edge does not clear it
  uint32_t digital_inputs = 0x00010000;  // 0x60FD as wired: bit 16 = e-stop chain closed (clear it to open the chain)
  // Power stage lost (STO active / e-stop contactor open / DC link gone),
  // without a CANopen fault: 0x6041 bit 4 (voltage enabled) reads 0 in every
  // state, no force is applied, and transition 3 (Switch on, needs high
  // voltage) is refused. A drive in Switched on / Operation enabled / Quick
  // stop active falls to `power_loss_state`: Switch on disabled (default) or
  // Ready to switch on; with Operation enabled it keeps its state and only
  // clears bit 4 (then, when power returns, it would apply the commanded
  // torque again by itself unless the master disables it). Clear it to
  // restore the power; the drive stays where it fell.
  bool power_stage_lost = false;
  cia402::State power_loss_state = cia402::State::SwitchOnDisabled;
};

class SimulatedDrive {
 public:
  explicit SimulatedDrive(const SimDriveParams& p);

  void process(int64_t now_us, std::span<const CanFrame> rx, FrameBuffer& tx);
  void poll(int64_t now_us, CanPort& port);

  // Fault injection.
  SimFaults& faults() { return faults_; }
  void inject_emcy(uint16_t code, uint8_t error_register, bool enters_fault, uint32_t event_status = 0);
  void enter_fault(uint16_t emcy_code, uint32_t event_status);
  void power_cycle(int64_t now_us, int64_t off_us);  // e-stop: power off, later boot
  void set_external_force(double f_n) { external_force_n_ = f_n; }
  // external_plant only: the stage state the encoder reports (drive axis, SI).
  void set_plant_state(double position_m, double velocity_mps) {
    position_m_ = position_m;
    velocity_mps_ = velocity_mps;
  }

  // Observation (tests and the fake-drive program).
  uint8_t node_id() const { return p_.node_id; }
  NmtState nmt_state() const { return nmt_; }
  cia402::State state() const { return state_; }
  uint16_t statusword() const;
  double position_m() const { return position_m_; }
  double velocity_mps() const { return velocity_mps_; }
  double applied_force_n() const { return applied_force_n_; }
  int16_t target_torque_permille() const { return target_torque_; }
  uint16_t controlword() const { return controlword_; }      // last received 0x6040
  uint32_t fault_resets() const { return fault_resets_; }    // CiA 402 transitions 15 taken
  uint32_t sync_count() const { return sync_count_; }
  uint32_t rpdo_count() const { return rpdo_count_; }
  uint32_t sdo_requests() const { return sdo_requests_; }
  bool powered() const { return powered_; }
  uint32_t od_value(uint16_t index, uint8_t sub) const;

 private:
  struct Entry {
    uint16_t index;
    uint8_t sub;
    uint8_t bytes;
    bool writable;
    bool mappable;
    uint32_t value;
    uint32_t initial;
  };
  void build_od();
  Entry* find(uint16_t index, uint8_t sub);
  const Entry* find(uint16_t index, uint8_t sub) const;
  uint32_t read_object(uint16_t index, uint8_t sub, bool& ok, uint32_t& abort) const;
  uint32_t write_object(uint16_t index, uint8_t sub, uint32_t value, std::size_t bytes);
  void reset_application();
  void reset_communication();
  void boot(int64_t now, FrameBuffer& tx);
  void on_nmt(const CanFrame& f, int64_t now);
  void on_sdo(const CanFrame& f, int64_t now, FrameBuffer& tx);
  void on_sync(int64_t now, FrameBuffer& tx);
  void on_rpdo(int n, const CanFrame& f);
  void apply_rpdo(int n);
  void apply_controlword(uint16_t cw);
  void step_state_machine();
  void apply_power_loss(cia402::State before);
  void send_emcy(uint16_t code, uint8_t reg, uint32_t mfr, FrameBuffer& tx);
  void integrate(double dt);
  int32_t position_counts() const;
  int32_t velocity_units() const;
  uint32_t live_value(uint16_t index) const;

  SimDriveParams p_;
  SimFaults faults_;
  std::vector<Entry> od_;
  NmtState nmt_ = NmtState::BootUp;
  bool powered_ = true;
  bool booted_ = false;
  int64_t boot_at_us_ = -1;     // pending boot-up time
  int64_t last_now_us_ = -1;
  int64_t next_heartbeat_us_ = 0;
  int64_t last_sync_us_ = -1;
  int64_t master_hb_last_us_ = -1;  // heartbeat consumer (0x1016), -1 = not yet seen
  cia402::State state_ = cia402::State::SwitchOnDisabled;
  uint16_t controlword_ = 0;
  uint16_t prev_controlword_ = 0;
  int16_t target_torque_ = 0;
  bool fault_pending_ = false;
  uint32_t fault_resets_ = 0;
  uint16_t pending_emcy_code_ = 0;
  bool emcy_pending_ = false;
  uint8_t emcy_reg_ = 0;
  uint32_t emcy_mfr_ = 0;
  bool reset_emcy_pending_ = false;
  CanFrame rpdo_buf_[4]{};
  bool rpdo_fresh_[4]{};
  uint32_t sync_count_ = 0;
  uint32_t rpdo_count_ = 0;
  uint32_t sdo_requests_ = 0;
  double position_m_ = 0;
  double velocity_mps_ = 0;
  double applied_force_n_ = 0;
  double external_force_n_ = 0;
  // SDO server segmented transfer state
  int sdo_op_ = 0;  // 0 none, 1 segmented upload, 2 segmented download
  bool sdo_toggle_ = false;
  std::string sdo_buf_;
  std::size_t sdo_offset_ = 0;
  uint16_t sdo_index_ = 0;
  uint8_t sdo_sub_ = 0;
  std::string user_string_;  // 0x2F00: writable string (segmented download target)
  struct Delayed {
    int64_t at_us;
    CanFrame frame;
  };
  std::array<Delayed, 16> delayed_{};  // TPDOs held back by faults_.tpdo_delay_us
  std::size_t n_delayed_ = 0;
};

}  // namespace manip::canopen
