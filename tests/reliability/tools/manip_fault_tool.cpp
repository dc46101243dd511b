// manip_fault_tool: the hostile neighbour and the log inspector of the fault
// matrix (tests/reliability/fault_matrix.sh). Not installed.
//
//   send URL malformed LEN        one command_t whose sender length field is LEN
//   send URL garbage N            N packets of random bytes (1..300 B) on MANIP_COMMAND
//   send URL flood N              N valid PERTURBATIONS_ON commands, counts the answers
//   send URL storm N              N ESTOP/FAULT_RESET pairs
//   send URL estop 1              one ESTOP (latched to the end of the run)
//   check LOG                     reads a manip_rt log and prints one line of facts:
//                                 events, states, first..last cycle, gaps, last mode,
//                                 STOPPED cycles at the end, faults, history states,
//                                 bytes skipped, truncated tail
#include <lcm/lcm-cpp.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "manip/command_status_t.hpp"
#include "manip/command_t.hpp"
#include "manip/fault_t.hpp"
#include "manip/logging/event_log.hpp"
#include "manip/state_t.hpp"

namespace {

std::vector<std::uint8_t> encode(const manip::command_t& c) {
  std::vector<std::uint8_t> b(static_cast<std::size_t>(c.getEncodedSize()));
  c.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}
manip::command_t command(std::int8_t kind, std::int64_t seq) {
  manip::command_t c{};
  c.seq = seq;
  c.sender = "fault_matrix";
  c.kind = kind;
  c.start_shoulder_m[1] = 0.30;
  c.goal_shoulder_m[1] = 0.55;
  return c;
}

struct Answers {
  long long n{0}, queue_full{0}, undecodable{0};
  void on(const lcm::ReceiveBuffer*, const std::string&, const manip::command_status_t* st) {
    ++n;
    if (st->reason.find("queue full") != std::string::npos) ++queue_full;
    if (st->reason.find("undecodable") != std::string::npos) ++undecodable;
  }
};

int send(const std::string& url, const std::string& what, long long n) {
  lcm::LCM lcm(url);
  if (!lcm.good()) {
    std::fprintf(stderr, "manip_fault_tool: cannot create LCM with %s\n", url.c_str());
    return 10;
  }
  Answers ans;
  auto* sub = lcm.subscribe("MANIP_COMMAND_STATUS", &Answers::on, &ans);
  sub->setQueueCapacity(1000000);
  lcm_t* c = lcm.getUnderlyingLCM();
  auto pump = [&] {
    while (lcm.handleTimeout(0) > 0) {
    }
  };
  std::mt19937_64 rng(12345);
  long long sent = 0;
  if (what == "malformed") {
    auto b = encode(command(manip::command_t::PAUSE, 1));
    const auto len = static_cast<std::uint32_t>(static_cast<std::int32_t>(n));
    // fingerprint (8), utime (8), seq (8), then the sender's length
    b[24] = static_cast<std::uint8_t>(len >> 24);
    b[25] = static_cast<std::uint8_t>(len >> 16);
    b[26] = static_cast<std::uint8_t>(len >> 8);
    b[27] = static_cast<std::uint8_t>(len);
    lcm_publish(c, "MANIP_COMMAND", b.data(), static_cast<unsigned>(b.size()));
    sent = 1;
  } else if (what == "garbage") {
    std::vector<std::uint8_t> b(300);
    for (long long i = 0; i < n; ++i) {
      const std::size_t len = 1 + rng() % b.size();
      for (auto& x : b) x = static_cast<std::uint8_t>(rng());
      lcm_publish(c, "MANIP_COMMAND", b.data(), static_cast<unsigned>(len));
      ++sent;
      if (i % 64 == 0) pump();
    }
  } else if (what == "flood" || what == "storm") {
    for (long long i = 0; i < n; ++i) {
      if (what == "flood") {
        const auto b = encode(command(manip::command_t::PERTURBATIONS_ON, i));
        lcm_publish(c, "MANIP_COMMAND", b.data(), static_cast<unsigned>(b.size()));
        ++sent;
      } else {
        for (std::int8_t k : {manip::command_t::ESTOP, manip::command_t::FAULT_RESET}) {
          const auto b = encode(command(k, 2 * i + (k == manip::command_t::FAULT_RESET)));
          lcm_publish(c, "MANIP_COMMAND", b.data(), static_cast<unsigned>(b.size()));
          ++sent;
        }
      }
      if (i % 64 == 0) pump();
    }
  } else if (what == "estop") {
    const auto b = encode(command(manip::command_t::ESTOP, 1));
    lcm_publish(c, "MANIP_COMMAND", b.data(), static_cast<unsigned>(b.size()));
    sent = 1;
  } else {
    std::fprintf(stderr, "manip_fault_tool: unknown send mode %s\n", what.c_str());
    return 2;
  }
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(500);
  while (std::chrono::steady_clock::now() < until) lcm.handleTimeout(20);
  std::printf("sent %lld answered %lld queue_full %lld undecodable %lld\n", sent, ans.n, ans.queue_full,
              ans.undecodable);
  return 0;
}

int check(const std::string& path) {
  try {
    manip::logging::EventLogReader rd(path);
    manip::logging::RawEvent ev;
    long long events = 0, states = 0, gaps = 0, faults = 0, history = 0, stopped_tail = 0, undecodable = 0;
    long long first = -1, last = -1;
    int last_mode = -1;
    bool session_first = false;
    while (rd.next(ev)) {
      if (events == 0) session_first = ev.channel == "MANIP_SESSION";
      ++events;
      if (ev.channel == "MANIP_STATE") {
        manip::state_t s;
        if (!manip::logging::decode(ev, s)) {
          ++undecodable;
          continue;
        }
        if (first < 0) first = s.cycle;
        if (last >= 0 && s.cycle != last + 1) gaps += s.cycle - last - 1;
        last = s.cycle;
        last_mode = s.mode;
        stopped_tail = s.mode == manip::state_t::MODE_STOPPED ? stopped_tail + 1 : 0;
        ++states;
      } else if (ev.channel == "MANIP_FAULT") {
        manip::fault_t f;
        if (!manip::logging::decode(ev, f)) {
          ++undecodable;
          continue;
        }
        ++faults;
        history += f.n_history;
      }
    }
    const auto& d = rd.diagnostics();
    std::printf(
        "session_first %d events %lld states %lld cycles %lld..%lld gaps %lld last_mode %d stopped_tail %lld "
        "faults %lld history %lld undecodable %lld skipped_bytes %llu truncated_tail %d bytes %llu\n",
        session_first ? 1 : 0, events, states, first, last, gaps, last_mode, stopped_tail, faults, history,
        undecodable, static_cast<unsigned long long>(d.bytes_skipped), d.truncated_tail ? 1 : 0,
        static_cast<unsigned long long>(rd.file_size()));
    return 0;
  } catch (const std::exception& e) {
    std::printf("unreadable: %s\n", e.what());
    return 4;
  }
}

}  // namespace

int main(int argc, char** argv) {
  const std::vector<std::string> a(argv + 1, argv + argc);
  if (a.size() == 4 && a[0] == "send") return send(a[1], a[2], std::atoll(a[3].c_str()));
  if (a.size() == 2 && a[0] == "check") return check(a[1]);
  std::fprintf(stderr, "usage: manip_fault_tool send URL malformed|garbage|flood|storm N | check LOG\n");
  return 2;
}
