#include "manip/canopen/bus_load.hpp"

#include <cstdio>

namespace manip::canopen {

std::vector<BusBudget> compute_budgets(const CanConfig& cfg) {
  std::vector<BusBudget> out;
  const double sync_hz = 1e6 / cfg.master.sync_period_us;
  for (const auto& bus : cfg.buses) {
    BusBudget b;
    b.bus = bus.name;
    b.interface = bus.interface;
    b.bitrate = bus.bitrate;
    b.sync_period_us = cfg.master.sync_period_us;
    b.limit = cfg.master.max_bus_load;
    auto add = [&](std::string what, int bytes, double hz, bool cyclic) {
      BudgetLine l{std::move(what), bytes, frame_bits_worst(bytes), hz};
      if (cyclic) b.cyclic_bits_per_sync += l.bits_per_frame;
      b.lines.push_back(std::move(l));
    };
    add("SYNC (0x080)", 0, sync_hz, true);
    int nodes = 0;
    for (const auto& d : cfg.drives) {
      if (d.bus != bus.name) continue;
      ++nodes;
      char name[64];
      std::snprintf(name, sizeof name, "RPDO1 node %u (%s)", d.node_id, d.name.c_str());
      add(name, d.rpdo.bytes(), sync_hz, true);
      std::snprintf(name, sizeof name, "TPDO1 node %u (%s)", d.node_id, d.name.c_str());
      add(name, d.tpdo.bytes(), sync_hz, true);
      if (d.tpdo2.count > 0) {
        std::snprintf(name, sizeof name, "TPDO2 node %u (%s)", d.node_id, d.name.c_str());
        add(name, d.tpdo2.bytes(), sync_hz, true);
      }
      std::snprintf(name, sizeof name, "heartbeat node %u", d.node_id);
      add(name, 1, 1000.0 / d.heartbeat_producer_ms, false);
      std::snprintf(name, sizeof name, "EMCY headroom node %u", d.node_id);
      add(name, 8, cfg.master.emcy_headroom_hz, false);
    }
    if (nodes > 0) add("heartbeat master", 1, 1000.0 / cfg.master.heartbeat_ms, false);
    for (const auto& l : b.lines) b.bits_per_s += l.bits_per_s();
    b.load = b.bits_per_s / b.bitrate;
    out.push_back(std::move(b));
  }
  return out;
}

std::string BusBudget::table() const {
  std::string s;
  char buf[200];
  std::snprintf(buf, sizeof buf, "bus %s (%s, %u bit/s, SYNC every %.0f us), worst case incl. stuffing:\n",
                bus.c_str(), interface.c_str(), bitrate, sync_period_us);
  s += buf;
  std::snprintf(buf, sizeof buf, "  %-34s %5s %6s %10s %11s\n", "frame", "bytes", "bits", "frames/s", "bit/s");
  s += buf;
  for (const auto& l : lines) {
    std::snprintf(buf, sizeof buf, "  %-34s %5d %6d %10.1f %11.0f\n", l.what.c_str(), l.data_bytes,
                  l.bits_per_frame, l.frames_per_s, l.bits_per_s());
    s += buf;
  }
  std::snprintf(buf, sizeof buf,
                "  cyclic bits per SYNC period: %d of %.0f\n  total %.0f bit/s = %.1f %% of the bus (limit %.1f %%): %s\n",
                cyclic_bits_per_sync, sync_period_us * 1e-6 * bitrate, bits_per_s, 100 * load, 100 * limit,
                ok() ? "OK" : "REFUSED");
  s += buf;
  return s;
}

}  // namespace manip::canopen
