// manip_vcan_session: the guest side of scripts/qemu_vcan_test.sh. Runs the
// CANopen master (CanDriveSet on SocketCAN, one bus per drive) against
// simulated drives in other processes (manip_fake_drive) on real kernel vcan
// interfaces: SDO start-up, CiA 402 enable, a cyclic phase at the configured
// SYNC rate driven by this loop's own 4 kHz cycle, disable, shutdown. A
// second raw socket per interface (no filter, SO_TIMESTAMPNS) sniffs every
// frame on the wire; the cyclic window is checked:
//   - every SYNC answered: RPDO1, TPDO1 (and TPDO2) counts equal the SYNC count (+-2 at the edges);
//   - SYNC count against what the loop could send: at least --min-rate-fraction
//     of min(SYNC periods in the window, loop cycles run). The master can only
//     send at a write(), so an emulated guest that runs the loop at a fraction
//     of 4 kHz (host load) lowers the achievable count; a stalled master does not
//     depend on the host and is caught the same on any machine;
//   - zero unexpected frames (anything but SYNC, RPDO1, TPDO1/2, heartbeats, EMCY = 0);
//   - SYNC period statistics from kernel receive timestamps (reported; the
//     median never early by more than --sync-tolerance, and late by at most
//     max(--sync-median-max x the period, the period + 2 x the loop's median
//     cycle): a due SYNC goes out at the first write() at or after its due time,
//     so an interval exceeds the period by at most the loop cycle that straddles
//     the deadline, and a random deadline lands in a long cycle more often than
//     in a short one, hence twice the median cycle);
//   - PDO round trip SYNC -> TPDO1 (reported only).
// Prints one "VCAN_RESULT PASS|FAIL ..." line; exit 0 on PASS, 1 on FAIL, 3 on set-up errors.
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "manip/canopen/bus_load.hpp"
#include "manip/canopen/drive_set.hpp"
#include "manip/canopen/socketcan.hpp"

namespace cc = manip::canopen;

namespace {

int64_t mono_us() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return int64_t(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
}
int64_t real_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return int64_t(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

struct Sniffer {
  int fd = -1;
  std::string iface;
  struct Rec {
    int64_t t_ns;  // kernel receive timestamp (CLOCK_REALTIME)
    uint32_t id;
  };
  std::vector<Rec> recs;
  bool open(const std::string& name) {
    iface = name;
    fd = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK, CAN_RAW);
    if (fd < 0) return false;
    ifreq ifr{};
    std::snprintf(ifr.ifr_name, IFNAMSIZ, "%s", name.c_str());
    if (::ioctl(fd, SIOCGIFINDEX, &ifr) < 0) return false;
    const int on = 1;
    ::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on);
    int rcvbuf = 8 << 20;
    ::setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &rcvbuf, sizeof rcvbuf);
    sockaddr_can a{};
    a.can_family = AF_CAN;
    a.can_ifindex = ifr.ifr_ifindex;
    recs.reserve(400000);
    return ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  }
  void drain() {
    for (;;) {
      can_frame f{};
      char ctrl[CMSG_SPACE(sizeof(timespec))];
      iovec iov{&f, sizeof f};
      msghdr m{};
      m.msg_iov = &iov;
      m.msg_iovlen = 1;
      m.msg_control = ctrl;
      m.msg_controllen = sizeof ctrl;
      if (::recvmsg(fd, &m, MSG_DONTWAIT) < 0) return;
      int64_t t = real_ns();
      for (cmsghdr* c = CMSG_FIRSTHDR(&m); c; c = CMSG_NXTHDR(&m, c))
        if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_TIMESTAMPNS) {
          timespec ts;
          std::memcpy(&ts, CMSG_DATA(c), sizeof ts);
          t = int64_t(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
        }
      recs.push_back({t, f.can_id & CAN_EFF_MASK});
    }
  }
};

double pct(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, std::size_t(p / 100.0 * double(v.size())))];
}

}  // namespace

int main(int argc, char** argv) {
  std::string config = "/etc/bus.yml";
  double duration_s = 10.0, min_rate_fraction = 0.5, sync_tolerance = 0.10, sync_median_max = 1.10;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string k = argv[i];
    if (k == "--config") config = argv[i + 1];
    else if (k == "--duration") duration_s = std::atof(argv[i + 1]);
    else if (k == "--min-rate-fraction") min_rate_fraction = std::atof(argv[i + 1]);
    else if (k == "--sync-tolerance") sync_tolerance = std::atof(argv[i + 1]);
    else if (k == "--sync-median-max") sync_median_max = std::atof(argv[i + 1]);
    else {
      std::fprintf(stderr, "usage: manip_vcan_session [--config F] [--duration S] [--min-rate-fraction X] [--sync-tolerance X]\n");
      return 3;
    }
  }
  cc::CanConfig cfg;
  std::vector<std::string> errors;
  if (!cc::load_config(config, cfg, errors)) {
    for (const auto& e : errors) std::fprintf(stderr, "%s\n", e.c_str());
    return 3;
  }
  for (const auto& b : cc::compute_budgets(cfg)) std::printf("%s", b.table().c_str());
  std::vector<std::unique_ptr<cc::SocketCanPort>> ports;
  std::vector<cc::CanPort*> raw;
  std::vector<Sniffer> sniff(cfg.buses.size());
  for (std::size_t b = 0; b < cfg.buses.size(); ++b) {
    std::string err;
    auto p = cc::SocketCanPort::open(cfg.buses[b].interface, cc::master_filters(), err);
    if (!p) {
      std::fprintf(stderr, "%s: %s\n", cfg.buses[b].interface.c_str(), err.c_str());
      return 3;
    }
    raw.push_back(p.get());
    ports.push_back(std::move(p));
    if (!sniff[b].open(cfg.buses[b].interface)) {
      std::fprintf(stderr, "sniffer on %s: %s\n", cfg.buses[b].interface.c_str(), std::strerror(errno));
      return 3;
    }
  }
  const int64_t loop_us = 250;  // the 4 kHz control loop; SYNC every sync_period_us from it
  int64_t next = mono_us();
  auto drain_all = [&] {
    for (auto& s : sniff) s.drain();
  };
  cc::CanDriveSet set(cfg, raw);
  const cc::CanDriveSet::Ticker tick = [&] {
    next += loop_us;
    const int64_t now = mono_us();
    if (next < now) next = now;  // late (emulation): do not try to catch up
    timespec ts{time_t(next / 1'000'000), long((next % 1'000'000) * 1000)};
    clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
    drain_all();
    return mono_us();
  };
  const int64_t t_cfg0 = mono_us();
  if (const cc::Error e = set.configure(tick)) {
    std::printf("VCAN_RESULT FAIL start-up: %s\n", cc::describe(e).c_str());
    return 1;
  }
  const int64_t t_cfg1 = mono_us();
  if (const cc::Error e = set.enable(tick)) {
    std::printf("VCAN_RESULT FAIL enable: %s\n", cc::describe(e).c_str());
    return 1;
  }
  std::printf("start-up (NMT reset, SDO configuration, NMT start) %.1f ms, enable %.1f ms\n",
              (t_cfg1 - t_cfg0) / 1e3, (mono_us() - t_cfg1) / 1e3);
  // Cyclic window: starts after the first full SYNC period of enabled operation.
  const std::size_t nb = cfg.buses.size();
  std::vector<uint32_t> syncs0(nb);
  for (std::size_t b = 0; b < nb; ++b) syncs0[b] = set.master(b).syncs_sent();
  const int64_t w0_ns = real_ns(), w0_us = mono_us();
  int64_t cycles = 0, late = 0;
  std::vector<double> loop_cycle_us;
  loop_cycle_us.reserve(std::size_t(duration_s * 1e6 / double(loop_us)) + 16);
  bool faulted = false;
  const int64_t end_us = w0_us + int64_t(duration_s * 1e6);
  int64_t now = w0_us;
  while (now < end_us) {
    const int64_t due = next + loop_us;
    const int64_t before = now;
    now = tick();
    loop_cycle_us.push_back(double(now - before));
    if (now - due > loop_us) ++late;
    set.read(now);
    // write() every cycle: the master emits SYNC + RPDO when its SYNC period
    // is due (manip_rt writes at the drive ticks, which coincide natively; in
    // the emulated guest late cycles would otherwise halve the SYNC rate).
    const double f = 2.0 * std::sin(2 * M_PI * 1.0 * double(now - w0_us) * 1e-6);
    set.write(manip::Vec2(f, -f));
    ++cycles;
    if (set.faulted()) {
      faulted = true;
      break;
    }
  }
  const int64_t w1_ns = real_ns(), w1_us = mono_us();
  std::vector<uint32_t> syncs_sent(nb);
  for (std::size_t b = 0; b < nb; ++b) syncs_sent[b] = set.master(b).syncs_sent() - syncs0[b];
  const cc::Error fault = set.error();
  const cc::Error ed = set.disable(tick);
  const cc::Error es = set.shutdown(tick);
  drain_all();
  const double window_s = (w1_us - w0_us) * 1e-6;
  const double loop_p50_us = pct(loop_cycle_us, 50);
  std::printf("cyclic window %.3f s, %lld loop cycles (%.0f Hz achieved, 4000 configured), %lld late by > 1 cycle; "
              "loop cycle p50 %.1f us, p99 %.1f us, max %.1f us\n",
              window_s, (long long)cycles, cycles / window_s, (long long)late, loop_p50_us, pct(loop_cycle_us, 99),
              pct(loop_cycle_us, 100));
  if (faulted) std::printf("FAULT during the cyclic phase: %s\n", cc::describe(fault).c_str());
  if (ed) std::printf("disable: %s\n", cc::describe(ed).c_str());
  if (es) std::printf("shutdown: %s\n", cc::describe(es).c_str());

  bool pass = !faulted && !ed;
  std::string why;
  const double period_us = cfg.master.sync_period_us;
  for (std::size_t b = 0; b < nb; ++b) {
    uint32_t n_sync = 0, n_rpdo = 0, n_tpdo1 = 0, n_tpdo2 = 0, n_hb = 0, n_hbm = 0, n_emcy = 0, n_bad = 0;
    std::vector<double> periods, rtt;
    int64_t last_sync = -1;
    uint32_t first_bad = 0;
    const auto& d = set.master(b).drive(0);
    const uint32_t node = d.node_id;
    for (const auto& r : sniff[b].recs) {
      if (r.t_ns < w0_ns || r.t_ns > w1_ns) continue;
      const uint32_t id = r.id;
      if (id == 0x080) {
        ++n_sync;
        if (last_sync >= 0) periods.push_back((r.t_ns - last_sync) / 1e3);
        last_sync = r.t_ns;
      } else if (id == 0x200 + node) ++n_rpdo;
      else if (id == 0x180 + node) {
        ++n_tpdo1;
        if (last_sync >= 0) rtt.push_back((r.t_ns - last_sync) / 1e3);
      } else if (id == 0x280 + node && d.tpdo2.count > 0) ++n_tpdo2;
      else if (id == 0x700 + node) ++n_hb;
      else if (id == 0x700u + cfg.master.node_id) ++n_hbm;
      else if (id == 0x080 + node) ++n_emcy;
      else {
        if (!n_bad) first_bad = id;
        ++n_bad;
      }
    }
    const double hb_expected = window_s * 1000.0 / d.heartbeat_producer_ms;
    const double hbm_expected = window_s * 1000.0 / cfg.master.heartbeat_ms;
    std::printf("bus %s (%s): SYNC %u (sent by the master %u; configured rate %.0f Hz -> %.0f in the window, %.1f %%), "
                "RPDO1 %u, TPDO1 %u, TPDO2 %u, heartbeat node %u: %u (expected ~%.0f), heartbeat master %u (expected ~%.0f), "
                "EMCY %u, unexpected %u\n",
                cfg.buses[b].name.c_str(), cfg.buses[b].interface.c_str(), n_sync, syncs_sent[b], 1e6 / period_us,
                window_s * 1e6 / period_us, 100.0 * n_sync / (window_s * 1e6 / period_us), n_rpdo, n_tpdo1, n_tpdo2,
                node, n_hb, hb_expected, n_hbm, hbm_expected, n_emcy, n_bad);
    if (!periods.empty()) {
      double mean = 0, sq = 0;
      for (double p : periods) mean += p;
      mean /= double(periods.size());
      for (double p : periods) sq += (p - mean) * (p - mean);
      std::size_t within = 0;
      for (double p : periods) within += std::abs(p - period_us) <= sync_tolerance * period_us;
      std::printf("  SYNC period (kernel rx timestamps): mean %.1f us, std %.1f us, p1 %.1f, p50 %.1f, p99 %.1f, p99.9 %.1f, max %.1f us; "
                  "%.1f %% within +-%.0f %% of %.0f us\n",
                  mean, std::sqrt(sq / double(periods.size())), pct(periods, 1), pct(periods, 50), pct(periods, 99),
                  pct(periods, 99.9), pct(periods, 100), 100.0 * double(within) / double(periods.size()),
                  sync_tolerance * 100, period_us);
      std::printf("  PDO round trip SYNC -> TPDO1 (other process, emulated guest): p50 %.1f us, p99 %.1f us, max %.1f us\n",
                  pct(rtt, 50), pct(rtt, 99), pct(rtt, 100));
      // Never early by more than the tolerance; late by at most what the loop's
      // own cycle allows (header): the emulated guest's loop falls behind with
      // the host's load (CI: 656 Hz, SYNC median 873 us), the master then sends
      // at each write() past the due time and resynchronises.
      const double p50 = pct(periods, 50);
      const double late_max_us = std::max(sync_median_max * period_us, period_us + 2.0 * loop_p50_us);
      std::printf("  SYNC period median %.1f us: allowed [%.1f, %.1f] us (loop cycle median %.1f us)\n", p50,
                  (1.0 - sync_tolerance) * period_us, late_max_us, loop_p50_us);
      if (p50 < (1.0 - sync_tolerance) * period_us || p50 > late_max_us) {
        pass = false;
        why += " sync-median";
      }
    }
    // Every SYNC answered: equal counts up to the frames in flight at the window
    // edges, plus 0.2 % for the emulated guest's scheduling stalls of 20-70 ms
    // (a loaded TCG host showed 4 of 5476 unanswered at the edges; the virtual-bus
    // tests check the exact one-to-one answer without emulation).
    auto near = [](uint32_t x, uint32_t y) {
      const int64_t tol = std::max<int64_t>(2, static_cast<int64_t>(y) / 500);
      return std::abs(int64_t(x) - int64_t(y)) <= tol;
    };
    if (!near(n_rpdo, n_sync)) { pass = false; why += " rpdo!=sync"; }
    if (!near(n_tpdo1, n_sync)) { pass = false; why += " tpdo1!=sync"; }
    if (d.tpdo2.count > 0 && !near(n_tpdo2, n_sync)) { pass = false; why += " tpdo2!=sync"; }
    if (!near(n_sync, syncs_sent[b])) { pass = false; why += " sync-lost"; }
    const double sync_achievable = std::min(window_s * 1e6 / period_us, double(cycles));
    if (n_sync < min_rate_fraction * sync_achievable) { pass = false; why += " sync-rate"; }
    if (n_bad) {
      pass = false;
      char buf[64];
      std::snprintf(buf, sizeof buf, " unexpected-frames(first 0x%03X)", first_bad);
      why += buf;
    }
    if (n_emcy) { pass = false; why += " emcy"; }
    if (n_hb + 1 < 0.5 * hb_expected) { pass = false; why += " heartbeat-rate"; }
  }
  // After disable: no drive enabled (the fake drives report through the master).
  for (std::size_t b = 0; b < nb; ++b)
    if (cc::cia402::decode(set.master(b).node(0).statusword) == cc::cia402::State::OperationEnabled) {
      pass = false;
      why += " still-enabled";
    }
  std::printf("VCAN_RESULT %s%s\n", pass ? "PASS" : "FAIL", why.c_str());
  return pass ? 0 : 1;
}
