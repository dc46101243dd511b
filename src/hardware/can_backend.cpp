#include "manip/hardware/can_backend.hpp"

#include <time.h>

#include <cmath>
#include <iostream>
#include <numbers>

#include "manip/canopen/bus_load.hpp"

namespace manip::hardware {

namespace cc = manip::canopen;
namespace bs = control::backend_status;

canopen::CanConfig load_can_config(const std::string& path) {
  cc::CanConfig c;
  std::vector<std::string> errors;
  if (!cc::load_config(path, c, errors)) {
    std::string all;
    for (const auto& e : errors) all += (all.empty() ? "" : "\n") + e;
    throw ConfigError(all);
  }
  return c;
}

namespace {
ForceBoundaryParams boundary_params(const cc::BackendOptions& b) {
  ForceBoundaryParams p;
  p.tare = b.tare;
  p.tare_samples = b.tare_samples;
  p.full_scale_n = b.force_full_scale_n;
  p.stale_cycles = b.force_stale_cycles;
  p.rotation_deg = b.sensor_rotation_deg;
  return p;
}

// Which backend_status bit a CANopen fault raises: the drive itself reports a
// fault (CiA 402 Fault, a faulting EMCY, a reboot mid-session) -> kDriveFault;
// anything on the way (heartbeat, TPDOs, bus-off, refused sends, an
// unexpected node) -> kBackendError. Both latch the supervisor's kBackend fault.
std::uint32_t status_bit(const cc::Error& e) {
  switch (e.code) {
    // A drive that left Operation enabled by itself with 0x6041 bit 4
    // (voltage enabled) off lost its power stage: the e-stop chain / STO.
    case cc::ErrorCode::UncommandedDisable:
      return (e.value & cc::cia402::sw::kVoltageEnabled) ? bs::kDriveFault : bs::kHwEStopOpen;
    case cc::ErrorCode::EStopChain:
      return bs::kHwEStopOpen;
    case cc::ErrorCode::DriveFault:
    case cc::ErrorCode::EmcyFault:
    case cc::ErrorCode::NodeRebooted:
      return bs::kDriveFault;
    default:
      return bs::kBackendError;
  }
}
}  // namespace

CanBackend::CanBackend(const control::ControlConfig& law, const SimConfig& sim, const cc::CanConfig& can,
                       std::unique_ptr<ForceSource> sensor)
    : law_(law),
      sim_(sim),
      can_(can),
      virtual_(can.backend.virtual_bus),
      period_us_(std::llround(law.dt_s() * 1e6)),
      sensor_(std::move(sensor)),
      force_(boundary_params(can.backend)) {
  if (can.backend.record_raw_frames) recorder_ = std::make_unique<cc::FrameRecorder>(can.backend.raw_queue_frames);
  if (std::abs(law.dt_s() * 1e6 - double(period_us_)) > 1e-6)
    throw ConfigError("can backend: the loop period " + std::to_string(law.dt_s() * 1e6) +
                      " us is not a whole number of microseconds (the CANopen clock counts microseconds)");
}

CanBackend::~CanBackend() { shutdown(); }

std::int64_t CanBackend::clock_us() const {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
}

std::int64_t CanBackend::tick() {
  if (virtual_) {
    now_us_ = rig_->tick();
    return now_us_;
  }
  // Lifecycle phases (not the loop): sleep to the next loop period.
  const std::int64_t target = now_us_ + period_us_;
  timespec ts{};
  ts.tv_sec = target / 1'000'000;
  ts.tv_nsec = (target % 1'000'000) * 1000;
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
  now_us_ = clock_us();
  return now_us_;
}

void CanBackend::fail(const std::string& what, const cc::Error& e) {
  std::string msg = what + ": " + cc::describe(e);
  if (set_) {
    (void)set_->shutdown([this] { return tick(); });  // nothing was enabled; leave the drives pre-operational
    set_.reset();
  }
  ports_.clear();
  rig_.reset();
  plant_.reset();
  throw BackendError(msg);
}

void CanBackend::on_configure() {
  const auto& b = can_.backend;
  // The supervisor's saturation limit must be reachable by the boundary's
  // full-scale clamp, or a saturated sensor would read as a plausible force.
  if (law_.safety.sensor_saturation_n > b.force_full_scale_n)
    throw ConfigError(can_.source + ": backend.force_full_scale_n " + std::to_string(b.force_full_scale_n) +
                      " N is below the safety supervisor's sensor_saturation_n " +
                      std::to_string(law_.safety.sensor_saturation_n) + " N (saturation could not be detected)");
  if (b.force_sensor == "sim" && !virtual_ && !sensor_)
    throw ConfigError(can_.source + ": backend.force_sensor: 'sim' needs backend.virtual: true (--can-virtual)");
  const std::int64_t sync_us = can_.master.sync_period_us;
  if (sync_us % period_us_ != 0)
    throw ConfigError(can_.source + ": master.sync_period_us " + std::to_string(sync_us) +
                      " is not a multiple of the loop period " + std::to_string(period_us_) +
                      " us (SYNC is sent from the loop's cycle)");

  // Bus budget: refuse above the limit, print it either way.
  budget_text_.clear();
  bool ok = true;
  for (const auto& bb : cc::compute_budgets(can_)) {
    budget_text_ += bb.table();
    ok &= bb.ok();
  }
  std::cerr << budget_text_;
  if (!ok) throw BackendError("CAN bus load above master.max_bus_load: refusing to start\n" + budget_text_);

  std::vector<cc::CanPort*> ports;
  if (virtual_) {
    rig_ = std::make_unique<cc::VirtualRig>(can_, period_us_, [](cc::SimDriveParams& p) { p.external_plant = true; });
    ports = rig_->master_ports();
    plant_ = std::make_unique<SimBackend>(law_, sim_, make_sim_human(law_, sim_));
    plant_->configure();
    plant_->enable();
    plant_started_ = false;
    for (const auto& d : can_.drives) {
      axis_drive_[std::size_t(d.workspace_axis)] = rig_->drive_by_node(d.bus, d.node_id);
      axis_sign_[std::size_t(d.workspace_axis)] = d.sign;
    }
    const Vec2 x = plant_->true_position_workspace_m();
    for (int a = 0; a < 2; ++a)
      if (axis_drive_[std::size_t(a)]) axis_drive_[std::size_t(a)]->set_plant_state(axis_sign_[std::size_t(a)] * x[a], 0.0);
    now_us_ = rig_->now();
    if (before_startup) before_startup(*rig_);
  } else {
    for (const auto& bus : can_.buses) {
      std::string err;
      auto p = cc::SocketCanPort::open(bus.interface, cc::master_filters(), err);
      if (!p) {
        ports_.clear();
        throw BackendError("CAN bus '" + bus.name + "' (" + bus.interface + "): " + err);
      }
      ports.push_back(p.get());
      ports_.push_back(std::move(p));
    }
    now_us_ = clock_us();
  }
  set_ = std::make_unique<cc::CanDriveSet>(can_, ports);
  if (recorder_) {
    recorder_->set_cycle(-1);  // start-up traffic (NMT, SDO list) is recorded too
    set_->set_recorder(recorder_.get());
  }
  const cc::Error e = set_->configure([this] { return tick(); });
  if (e) fail("CANopen start-up failed (nothing enabled)", e);

  // --can-virtual always uses the simulated sensor (a rehearsal has no real one).
  if (!sensor_ && !virtual_ && b.force_sensor == "netft")
    sensor_ = std::make_unique<NetFtClient>(b.netft_address, static_cast<std::uint16_t>(b.netft_port),
                                            b.netft_counts_per_force);
  if (!sensor_ && !virtual_ && b.force_sensor == "jr3")
    sensor_ = std::make_unique<Jr3Source>(std::make_unique<Jr3PciDevice>(b.jr3_device), b.jr3_filter);
  if (sensor_) {
    std::string err;
    if (!sensor_->start(err)) fail("force sensor: " + err, cc::Error{cc::ErrorCode::OperatorStop});
  }
  latch_ = Latch::kNone;
  latched_error_ = {};
}

void CanBackend::on_enable() {
  const cc::Error e = set_->enable([this] { return tick(); });
  if (e) {
    (void)set_->disable([this] { return tick(); });
    throw BackendError("CiA 402 enable failed: " + cc::describe(e));
  }
  force_.begin_session();
  latch_ = Latch::kNone;
  latched_error_ = {};
  last_write_us_ = now_us_;
  loop_cycle_ = -1;  // the first read() is loop cycle 0
  fault_seen_ = false;
  estop_open_ = false;
  stale_ = false;
  reset_ = Reset::kNone;
  resets_failed_seen_ = set_->fault_resets_failed();
}

void CanBackend::on_disable() noexcept {
  loop_cycle_ = -1;
  if (recorder_) recorder_->set_cycle(-1);
  if (set_) (void)set_->disable([this] { return tick(); });
}

void CanBackend::on_shutdown() noexcept {
  if (set_) {
    const cc::Error e = set_->shutdown([this] { return tick(); });
    if (e && latch_ == Latch::kNone) {
      latch_ = Latch::kCanopen;
      latched_error_ = e;
      Note n;
      n.kind = Latch::kCanopen;
      n.error = e;
      note(n);  // the logger is still running during shutdown (runtime::run_session)
    }
    // Copley's event status register, read by SDO after the session when it
    // ended with a fault (event_status_register: true): into the log too.
    for (std::size_t b = 0; b < set_->bus_count(); ++b)
      for (std::size_t s = 0; s < set_->master(b).node_count(); ++s) {
        const cc::NodeStatus& ns = set_->master(b).node(s);
        if (!ns.identity.event_status_read) continue;
        Note n;
        n.kind = Latch::kEventStatus;
        n.error.node = ns.node_id;
        n.error.value = ns.identity.event_status;
        note(n);
      }
  }
  if (sensor_) sensor_->stop();
  if (latch_ != Latch::kNone) std::cerr << "can backend: fault: " << fault_reason() << "\n";
  ports_.clear();
}

std::string CanBackend::fault_reason() const {
  Note n;
  n.kind = latch_;
  n.error = latched_error_;
  n.axis = estop_axis_;
  n.statusword = estop_statusword_;
  n.by_input = estop_by_input_;
  n.inputs = estop_inputs_;
  return describe(n);
}

std::string CanBackend::describe(const Note& n) const {
  switch (n.kind) {
    case Latch::kNone: return "";
    case Latch::kCanopen: return cc::describe(n.error);
    case Latch::kEStop: {
      char buf[200];
      if (n.by_input) {
        std::snprintf(buf, sizeof buf,
                      "e-stop chain open: digital input bit %d (0x60FD = 0x%08X) of the drive of workspace axis %d "
                      "reads the open level (statusword 0x%04X)",
                      can_.backend.estop_input_bit, n.inputs, n.axis, n.statusword);
        return buf;
      }
      std::snprintf(buf, sizeof buf,
                    "e-stop chain open / safe torque off reported by the drive of workspace axis %d (statusword 0x%04X)",
                    n.axis, n.statusword);
      return buf;
    }
    case Latch::kEventStatus: {
      char buf[80];
      std::snprintf(buf, sizeof buf, "node %u: event status register 0x1002 after the fault = 0x%08X: ", n.error.node,
                    n.error.value);
      const std::string names = cc::copley_event_status_text(n.error.value);
      return buf + (names.empty() ? std::string("no bit set") : names);
    }
    case Latch::kSensorStale:
      return "force sensor stale: no usable sample for " + std::to_string(can_.backend.force_stale_cycles) +
             " control cycles (or the sensor reported an error)";
  }
  return "";
}

void CanBackend::step_virtual_plant() {
  // The force each simulated drive applies (from its CAN target torque, held
  // between SYNCs like a real CST drive) acts on the sim backend's stages.
  for (int a = 0; a < 2; ++a)
    plant_force_n_[a] = axis_drive_[std::size_t(a)]
                            ? axis_sign_[std::size_t(a)] * axis_drive_[std::size_t(a)]->applied_force_n()
                            : 0.0;
  control::ActuatorCommand c;
  c.f_motor_n = plant_force_n_;
  c.enable = true;
  c.send = true;
  plant_->write(c);
  plant_->read(plant_reading_);  // advances the plant by one loop period (not on the first call)
  const Vec2 x = plant_->true_position_workspace_m();
  const Vec2 v = plant_->true_velocity_workspace_mps();
  for (int a = 0; a < 2; ++a)
    if (axis_drive_[std::size_t(a)])
      axis_drive_[std::size_t(a)]->set_plant_state(axis_sign_[std::size_t(a)] * x[a], axis_sign_[std::size_t(a)] * v[a]);
  now_us_ = rig_->tick();  // the drives answer this cycle's SYNC with the new state
}

void CanBackend::read(control::SensorReading& out) {
  ++cycles_;
  ++loop_cycle_;
  if (recorder_) recorder_->set_cycle(loop_cycle_);
  if (virtual_) step_virtual_plant();
  else now_us_ = clock_us();
  // Keep SYNC, RPDOs and the master heartbeat going (with zero force) if
  // the controller did not send for two SYNC periods (it sends at every
  // drive tick, i.e. every SYNC period).
  if (now_us_ - last_write_us_ >= 2 * std::int64_t(can_.master.sync_period_us)) {
    last_force_n_.setZero();
    set_->write(last_force_n_);
    last_write_us_ = now_us_;
  }
  const cc::DriveSetFeedback& fb = set_->read(now_us_);
  out.x_workspace_m = fb.position_m;
  out.xd_workspace_mps = fb.velocity_mps;
  std::uint64_t pos_seq = 0;
  for (std::size_t b = 0; b < set_->bus_count(); ++b)
    for (std::size_t s = 0; s < set_->master(b).node_count(); ++s) pos_seq += set_->master(b).node(s).tpdo_received;
  out.position_seq = pos_seq;

  // Force sensor through the boundary.
  ForceSample sample;
  bool fresh = false;
  if (sensor_) {
    fresh = sensor_->poll(sample);
  } else if (virtual_) {
    // The simulated sensor reports in the workspace frame: express it in the
    // configured sensor frame so the boundary's rotation is exercised.
    const double a = -can_.backend.sensor_rotation_deg * std::numbers::pi / 180.0;
    const Vec2 f = plant_reading_.f_sensor_workspace_n;
    sample.f_sensor_n = Vec2(std::cos(a) * f[0] - std::sin(a) * f[1], std::sin(a) * f[0] + std::cos(a) * f[1]);
    sample.seq = plant_reading_.force_seq;
    fresh = true;
  } else {
    fresh = true;  // force_sensor: none -> zero force, always fresh
  }
  const ForceBoundary::Out& fo = force_.update(sample, fresh);
  out.f_sensor_workspace_n = fo.f_workspace_n;
  out.force_seq = fo.seq;

  std::uint32_t st = 0;
  if (fb.enabled) st |= bs::kDrivesEnabled;
  // Safety inputs, every cycle: the e-stop chain / STO as the drives report it.
  const auto& bo = can_.backend;
  for (int a = 0; a < 2; ++a) {
    const std::uint16_t sw = fb.statusword[std::size_t(a)];
    const std::uint32_t di = fb.digital_inputs[std::size_t(a)];
    bool open = false, by_input = false;
    if (bo.estop_statusword_bit >= 0) open |= (((sw >> bo.estop_statusword_bit) & 1u) != 0) == bo.estop_active_high;
    // The chain's own contact on a drive input, CiA 402 0x60FD in a TPDO
    // (fresh every SYNC period).
    if (bo.estop_input_bit >= 0 && (((di >> bo.estop_input_bit) & 1u) != 0) == bo.estop_input_open_high) {
      open = true;
      by_input = true;
    }
    // CiA 402 0x6041 bit 4 (voltage enabled) gone while Operation enabled: the
    // power stage lost its supply (STO / e-stop contactor).
    if (bo.estop_on_voltage_loss && fb.state[std::size_t(a)] == cc::cia402::State::OperationEnabled &&
        !(sw & cc::cia402::sw::kVoltageEnabled))
      open = true;
    if (open) {
      if (!(st & bs::kHwEStopOpen) && !estop_open_) {  // the chain opened in this cycle: note it
        Note n;
        n.cycle = loop_cycle_;
        n.status = bs::kHwEStopOpen;
        n.kind = Latch::kEStop;
        n.axis = a;
        n.statusword = sw;
        n.by_input = by_input;
        n.inputs = di;
        note(n);
      }
      st |= bs::kHwEStopOpen;
      if (latch_ == Latch::kNone) {
        latch_ = Latch::kEStop;
        estop_axis_ = a;
        estop_statusword_ = sw;
        estop_by_input_ = by_input;
        estop_inputs_ = di;
      }
    }
  }
  estop_open_ = (st & bs::kHwEStopOpen) != 0;
  if (estop_open_) {
    // An open chain disarms both drives now (safe state on every bus): when
    // it closes they stay disabled until the operator's FAULT_RESET, which
    // the supervisor refuses while the chain reads open (present).
    if (!set_->faulted()) {
      set_->stop(cc::Error{cc::ErrorCode::EStopChain, 0, 0, 0, 0, 0, now_us_});
      fault_seen_ = true;  // its reason is the e-stop note above
      reset_ = Reset::kNone;
    } else if (!fault_seen_ && set_->error().code == cc::ErrorCode::UncommandedDisable) {
      fault_seen_ = true;  // the master saw the same event (the drive dropped out): one note, the e-stop's
      reset_ = Reset::kNone;
    }
  }
  if (fb.faulted || set_->faulted()) {
    cc::Error e = set_->error();
    std::uint32_t bit = status_bit(e);
    // Acknowledgeable faults raise their bit in the detecting cycle only (the
    // supervisor latches it; the master holds the drives disabled until the
    // operator's reset); faults that need a restart stay present.
    bool raise = !set_->fault_acknowledgeable();
    if (!fault_seen_) {
      fault_seen_ = true;
      raise = true;
      reset_ = Reset::kNone;
    } else if (reset_ == Reset::kClearing && set_->fault_resets_failed() != resets_failed_seen_) {
      // The edge went out but a drive stayed in Fault (its cause persists):
      // raise it again, with the master's reason.
      resets_failed_seen_ = set_->fault_resets_failed();
      reset_ = Reset::kNone;
      e = cc::Error{cc::ErrorCode::FaultResetFailed, 0, 0, 0, 0, 0, now_us_};
      for (std::size_t b = 0; b < set_->bus_count() && !e.node; ++b) {
        const cc::Master& m = set_->master(b);
        for (std::size_t i = m.log_count(); i-- > 0;)
          if (m.log_entry(i).code == cc::ErrorCode::FaultResetFailed) {
            e = m.log_entry(i);
            break;
          }
      }
      bit = bs::kDriveFault;
      raise = true;
    } else {
      e = {};  // already noted
    }
    if (e) {
      if (latch_ == Latch::kNone) {
        latch_ = Latch::kCanopen;
        latched_error_ = e;
      }
      Note n;
      n.cycle = loop_cycle_;
      n.status = bit;
      n.kind = Latch::kCanopen;
      n.error = e;
      note(n);
    }
    if (raise) st |= bit;
  } else {
    fault_seen_ = false;
    if (reset_ == Reset::kClearing) {  // every drive out of Fault: re-enable (CiA 402 2, 3, 4)
      set_->request_enable();
      reset_ = Reset::kEnabling;
      reset_deadline_us_ = now_us_ + std::int64_t(can_.master.enable_timeout_ms) * 1000;
    }
    if (reset_ == Reset::kEnabling) {
      if (fb.enabled) {
        reset_ = Reset::kNone;
      } else if (now_us_ > reset_deadline_us_) {
        reset_ = Reset::kNone;
        // Give up the walk: a drive waiting in Ready to switch on for its
        // power (transition 3) must not complete it later by itself.
        set_->cancel_enable();
        const cc::Error e{cc::ErrorCode::EnableTimeout, 0, 0, 0, 0, can_.master.enable_timeout_ms, now_us_};
        if (latch_ == Latch::kNone) {
          latch_ = Latch::kCanopen;
          latched_error_ = e;
        }
        Note n;
        n.cycle = loop_cycle_;
        n.status = bs::kDriveFault;
        n.kind = Latch::kCanopen;
        n.error = e;
        note(n);
        st |= bs::kDriveFault;
      }
    }
  }
  if (fo.stale) {
    st |= bs::kBackendError;
    if (!stale_) {
      Note n;
      n.cycle = loop_cycle_;
      n.status = bs::kBackendError;
      n.kind = Latch::kSensorStale;
      note(n);
    }
    if (latch_ == Latch::kNone) latch_ = Latch::kSensorStale;
  }
  stale_ = fo.stale;
  out.status = st;
  last_status_ = st;
}

void CanBackend::write(const control::ActuatorCommand& cmd) {
  last_force_n_ = cmd.enable ? cmd.f_motor_n : Vec2::Zero();
  set_->write(last_force_n_);
  last_write_us_ = now_us_;
}

void CanBackend::display(const control::DisplayCue& cue) {
  if (plant_) plant_->display(cue);
}

void CanBackend::note(const Note& n) noexcept {
  if (!notes_.try_push(n)) notes_dropped_.fetch_add(1, std::memory_order_relaxed);
}

void CanBackend::request_fault_reset() noexcept {
  if (!set_ || state() != BackendState::kActive) return;
  // The operator acknowledged: the next fault gets a fresh reason.
  latch_ = Latch::kNone;
  latched_error_ = {};
  if (set_->faulted()) {
    // False for a fault that needs a restart: read() keeps raising it, so
    // the supervisor refuses the reset in the first place.
    if (set_->request_fault_reset()) {
      reset_ = Reset::kClearing;
      resets_failed_seen_ = set_->fault_resets_failed();
    }
  } else if (!(last_status_ & bs::kDrivesEnabled)) {
    // E.g. after an enable timeout: try the CiA 402 enable path again.
    set_->request_enable();
    reset_ = Reset::kEnabling;
    reset_deadline_us_ = now_us_ + std::int64_t(can_.master.enable_timeout_ms) * 1000;
  }
}

bool CanBackend::next_fault_note(BackendFaultNote& out) {
  Note n;
  if (!notes_.try_pop(n)) return false;
  out.cycle = n.cycle;
  out.status = n.status;
  out.text = "can backend: " + describe(n);
  return true;
}

bool CanBackend::next_raw_batch(manip::can_frames_t& out, std::size_t max_frames) {
  if (!recorder_ || recorder_->size_approx() == 0) return false;
  out.n_interfaces = static_cast<std::int32_t>(can_.buses.size());
  out.interfaces.clear();
  for (const auto& b : can_.buses) out.interfaces.push_back(b.interface);
  out.cycle.clear();
  out.t_us.clear();
  out.iface.clear();
  out.id.clear();
  out.flags.clear();
  out.dlc.clear();
  out.data.clear();
  cc::RecordedFrame r;
  while (out.cycle.size() < max_frames && recorder_->pop(r)) {
    out.cycle.push_back(r.cycle);
    out.t_us.push_back(r.t_us);
    out.iface.push_back(static_cast<std::int8_t>(r.iface));
    out.id.push_back(static_cast<std::int32_t>(r.frame.id));
    std::int8_t fl = 0;
    if (r.tx) fl |= manip::can_frames_t::FLAG_TX;
    if (r.frame.is_error()) fl |= manip::can_frames_t::FLAG_ERROR;
    if (r.frame.is_rtr()) fl |= manip::can_frames_t::FLAG_RTR;
    out.flags.push_back(fl);
    out.dlc.push_back(static_cast<std::int8_t>(r.frame.dlc));
    std::vector<std::int8_t> d(8);
    for (int i = 0; i < 8; ++i) d[std::size_t(i)] = static_cast<std::int8_t>(r.frame.data[i]);
    out.data.push_back(std::move(d));
  }
  out.n = static_cast<std::int32_t>(out.cycle.size());
  out.dropped_total = recorder_->dropped();
  return out.n > 0;
}

}  // namespace manip::hardware
