#include "manip/canopen/can_check.hpp"

#include <cstdio>

namespace manip::canopen {

SimDriveParams sim_params_for(const DriveConfig& d) {
  SimDriveParams p;
  p.node_id = d.node_id;
  p.counts_per_m = d.counts_per_m;
  p.velocity_units_per_count_s = d.velocity_units_per_count_s;
  p.rated_current_a = d.rated_current_a;
  p.force_constant_n_per_a = d.force_constant_n_per_a;
  if (d.vendor_id) p.vendor_id = d.vendor_id;
  if (d.product_code) p.product_code = d.product_code;
  p.has_event_status = d.event_status_register;
  return p;
}

VirtualRig::VirtualRig(const CanConfig& cfg, int64_t step_us, const std::function<void(SimDriveParams&)>& tweak)
    : step_us_(step_us) {
  for (const auto& b : cfg.buses) {
    buses_.push_back(std::make_unique<VirtualBus>(b.bitrate));
    master_eps_.push_back(&buses_.back()->attach());
  }
  for (const auto& d : cfg.drives) {
    for (std::size_t b = 0; b < cfg.buses.size(); ++b) {
      if (cfg.buses[b].name != d.bus) continue;
      SimDriveParams p = sim_params_for(d);
      if (tweak) tweak(p);
      drives_.push_back(std::make_unique<SimulatedDrive>(p));
      drive_eps_.push_back(&buses_[b]->attach());
      drive_bus_.push_back(d.bus);
    }
  }
}

SimulatedDrive& VirtualRig::add_drive(std::size_t bus, const SimDriveParams& p) {
  drives_.push_back(std::make_unique<SimulatedDrive>(p));
  drive_eps_.push_back(&buses_[bus]->attach());
  drive_bus_.push_back("#" + std::to_string(bus));
  return *drives_.back();
}

int64_t VirtualRig::tick() {
  now_us_ += step_us_;
  for (auto& b : buses_) b->set_time(now_us_);
  for (std::size_t i = 0; i < drives_.size(); ++i) drives_[i]->poll(now_us_, *drive_eps_[i]);
  return now_us_;
}

std::vector<CanPort*> VirtualRig::master_ports() {
  std::vector<CanPort*> v;
  for (auto* e : master_eps_) v.push_back(e);
  return v;
}

SimulatedDrive* VirtualRig::drive_by_node(const std::string& bus, uint8_t node) {
  for (std::size_t i = 0; i < drives_.size(); ++i)
    if (drive_bus_[i] == bus && drives_[i]->node_id() == node) return drives_[i].get();
  return nullptr;
}

CheckResult run_can_check(const CanConfig& cfg, const std::vector<CanPort*>& ports, const CanDriveSet::Ticker& tick,
                          int sync_periods) {
  CheckResult r;
  char buf[512];
  bool budget_ok = true;
  for (const auto& b : compute_budgets(cfg)) {
    r.report += b.table();
    budget_ok &= b.ok();
  }
  if (!budget_ok) {
    r.report += "FAIL: worst-case bus load above master.max_bus_load: lower the SYNC rate, shrink the PDOs or use one bus per drive\n";
    r.exit_code = kCheckBudget;
    return r;
  }
  CanDriveSet set(cfg, ports);
  const Error e = set.configure(tick);
  for (std::size_t b = 0; b < set.bus_count(); ++b) {
    Master& m = set.master(b);
    for (std::size_t s = 0; s < m.node_count(); ++s) {
      const NodeStatus& n = m.node(s);
      const NodeIdentity& id = n.identity;
      std::snprintf(buf, sizeof buf,
                    "node %u (%s): NMT %s, device type 0x%08X, vendor 0x%08X, product 0x%08X, revision 0x%08X, "
                    "serial 0x%08X, name '%s', error register 0x%02X, rated current %u mA\n",
                    n.node_id, m.drive(s).name.c_str(), to_string(n.nmt), id.device_type, id.vendor_id,
                    id.product_code, id.revision, id.serial, id.name.data(), id.error_register, id.rated_current_ma);
      r.report += buf;
    }
  }
  if (e) {
    r.report += "FAIL: " + describe(e) + "\n";
    set.shutdown(tick);
    r.exit_code = kCheckDrive;
    return r;
  }
  r.report += "start-up OK: heartbeat producer/consumer, SYNC period, PDO mapping and mode 10 written and read back\n";
  int64_t now = tick();
  uint32_t syncs0 = 0;
  std::vector<std::vector<uint32_t>> tp0(set.bus_count());
  for (std::size_t b = 0; b < set.bus_count(); ++b) {
    for (std::size_t s = 0; s < set.master(b).node_count(); ++s) tp0[b].push_back(set.master(b).node(s).tpdo_received);
  }
  syncs0 = set.master(0).syncs_sent();
  while (set.master(0).syncs_sent() - syncs0 < static_cast<uint32_t>(sync_periods) && !set.faulted()) {
    set.read(now);
    set.write(Vec2::Zero());
    now = tick();
  }
  bool ok = !set.faulted();
  for (std::size_t b = 0; b < set.bus_count() && ok; ++b) {
    Master& m = set.master(b);
    for (std::size_t s = 0; s < m.node_count(); ++s) {
      const NodeStatus& n = m.node(s);
      const uint32_t got = n.tpdo_received - tp0[b][s];
      const uint32_t per_sync = 1 + (m.drive(s).tpdo2.count ? 1 : 0);
      const double rate = double(got) / (per_sync * double(sync_periods));
      std::snprintf(buf, sizeof buf, "node %u: %u TPDOs in %d SYNC periods (%.1f %% of the configured rate), %u missed\n",
                    n.node_id, got, sync_periods, 100 * rate, n.tpdo_missed_total);
      r.report += buf;
      if (rate < 0.99) ok = false;
    }
  }
  if (set.faulted()) r.report += "FAIL: " + describe(set.error()) + "\n";
  else if (!ok) r.report += "FAIL: configured PDO rate not achieved\n";
  set.shutdown(tick);
  r.exit_code = ok ? kCheckOk : kCheckDrive;
  if (ok) r.report += "OK: the bus is ready for manip_rt --backend can\n";
  return r;
}

}  // namespace manip::canopen
