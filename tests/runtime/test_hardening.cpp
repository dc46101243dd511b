// Issue 9 regressions on the runtime side: untrusted command bytes (string
// length fields <= 0 or too large must be answered, never thrown), a command
// storm must not multiply the fault history written, the session log is
// locked and a failed start leaves nothing behind, the log is flushed by
// cycles as well as by wall-clock time.
#include <catch2/catch.hpp>

#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <ostream>
#include <streambuf>
#include <string>
#include <vector>

#include "manip/command_t.hpp"
#include "manip/common/errors.hpp"
#include "manip/logging/event_log.hpp"
#include "manip/runtime/backends.hpp"
#include "manip/runtime/bus.hpp"
#include "manip/runtime/logger.hpp"
#include "manip/runtime/session.hpp"
#include "manip/state_t.hpp"

using manip::command_t;
using namespace manip::control;
using namespace manip::runtime;

namespace {
std::vector<std::uint8_t> encoded_pause() {
  command_t c{};
  c.seq = 5;
  c.sender = "x";
  c.kind = command_t::PAUSE;
  std::vector<std::uint8_t> b(static_cast<std::size_t>(c.getEncodedSize()));
  c.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}
// command_t: fingerprint (8), utime (8), seq (8), then sender's i32 length.
constexpr std::size_t kSenderLengthAt = 24;
void put_be32(std::vector<std::uint8_t>& b, std::size_t at, std::uint32_t v) {
  b[at] = static_cast<std::uint8_t>(v >> 24);
  b[at + 1] = static_cast<std::uint8_t>(v >> 16);
  b[at + 2] = static_cast<std::uint8_t>(v >> 8);
  b[at + 3] = static_cast<std::uint8_t>(v);
}
std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("manip_rthard_" + std::to_string(::getpid()) + "_" + name))
      .string();
}
}  // namespace

TEST_CASE("command gate: string length 0, negative or too large is answered as undecodable, never thrown",
          "[commands][hardening]") {
  CommandQueue q(8);
  CommandGate gate(q, CommandLimits::from_config(RtConfig{}));
  for (const std::uint32_t len : {0u, 0xFFFFFFFBu /* -5 */, 0x80000000u /* INT32_MIN */, 0x7FFFFFFFu, 1000u}) {
    auto b = encoded_pause();
    put_be32(b, kSenderLengthAt, len);
    INFO("sender length field " << static_cast<std::int32_t>(len));
    std::optional<manip::command_status_t> st;
    REQUIRE_NOTHROW(st = gate.submit(b.data(), static_cast<int>(b.size()), 0, 2));
    REQUIRE(st);
    CHECK_FALSE(st->accepted);
    CHECK(st->seq == -1);
    // the answer names the reason and the problem (which length, where)
    CHECK(st->reason.rfind(reject_text(Reject::kUndecodable), 0) == 0);
    CHECK(st->reason.find("length") != std::string::npos);
  }
  CHECK(q.size_approx() == 0);
  CHECK(gate.rejected() == 5);
  CHECK(gate.received() == 5);
}

TEST_CASE("logger: an ESTOP/FAULT_RESET storm writes each state at most once into fault histories",
          "[logger][hardening]") {
  const std::string path = temp_path("storm.lcm");
  std::filesystem::remove(path);
  RecordQueue q(1 << 16);
  Logger lg(q, 400, 10.0);
  lg.set_print_faults(false);
  manip::session_t s{};
  s.utime_start = 1;
  std::string err;
  // session_t has strings: give them valid contents
  REQUIRE(lg.open(path, s, err));
  // 4000 cycles, a fault notice every 2 cycles (ESTOP, reset, ESTOP, ...)
  for (std::int64_t k = 0; k < 4000; ++k) {
    manip::state_t st{};
    st.cycle = k;
    st.utime = k * 250;
    REQUIRE(q.try_push(LoopRecord(st)));
    if (k % 2 == 0) {
      FaultRecord f{};
      f.utime = k * 250;
      f.cycle = k;
      f.new_flags = 1;
      f.fault_flags = 1;
      REQUIRE(q.try_push(LoopRecord(f)));
    }
    if (k % 1000 == 999) lg.drain();
  }
  REQUIRE(lg.close(err));
  const LoggerStats st = lg.stats();
  CHECK(st.faults == 2000);
  // every state at most once in some fault's history: <= 4000 history states
  // in all, instead of 2000 x 400 (the storm of issue 9 item 5)
  CHECK(st.fault_history_states <= 4000);
  CHECK(st.fault_history_states >= 2000);
  std::filesystem::remove(path);
}

TEST_CASE("logger: flushed by cycles as well as by wall-clock time", "[logger][hardening]") {
  const std::string path = temp_path("flush.lcm");
  std::filesystem::remove(path);
  RecordQueue q(1 << 16);
  Logger lg(q, 10, 3600.0);  // wall-clock flush never due in this test
  lg.set_flush_every_cycles(100);
  manip::session_t s{};
  std::string err;
  REQUIRE(lg.open(path, s, err));
  for (std::int64_t k = 0; k < 1000; ++k) {
    manip::state_t st{};
    st.cycle = k;
    REQUIRE(q.try_push(LoopRecord(st)));
  }
  lg.drain();
  // what reached the OS (a kill -9 keeps it): everything up to the last multiple of 100 cycles
  struct stat sb {};
  REQUIRE(::stat(path.c_str(), &sb) == 0);
  manip::state_t probe{};
  const auto per_state = static_cast<off_t>(probe.getEncodedSize() + 28 + 11);  // header + "MANIP_STATE"
  CHECK(sb.st_size >= 900 * per_state);
  REQUIRE(lg.close(err));
  std::filesystem::remove(path);
}

TEST_CASE("logger: the log is locked for the session - a second instance is refused, the first intact",
          "[logger][hardening]") {
  const std::string path = temp_path("locked.lcm");
  std::filesystem::remove(path);
  RecordQueue q1(64), q2(64);
  Logger a(q1, 10, 1.0), b(q2, 10, 1.0);
  manip::session_t s{};
  std::string err;
  REQUIRE(a.open(path, s, err, /*force=*/false));
  const auto size_a = std::filesystem::file_size(path);
  CHECK(size_a > 0);
  err.clear();
  CHECK_FALSE(b.open(path, s, err, /*force=*/true));
  CHECK(err.find("in use") != std::string::npos);
  CHECK(std::filesystem::file_size(path) == size_a);  // not truncated by the refused attempt
  err.clear();
  CHECK_FALSE(b.open(path, s, err, /*force=*/false));
  CHECK(err.find("exists") != std::string::npos);
  REQUIRE(a.close(err));
  CHECK(std::filesystem::file_size(path) == size_a);
  std::filesystem::remove(path);
}

TEST_CASE("logger: discard() after a failed start leaves no stub log", "[logger][hardening]") {
  const std::string path = temp_path("stub.lcm");
  std::filesystem::remove(path);
  RecordQueue q(64);
  Logger lg(q, 10, 1.0);
  manip::session_t s{};
  std::string err;
  REQUIRE(lg.open(path, s, err, false));
  REQUIRE(std::filesystem::exists(path));
  lg.discard();
  CHECK_FALSE(std::filesystem::exists(path));
}

namespace {
// A stream whose every write fails, with exceptions on: what a supervisor
// thread meets when something it calls throws.
struct FailingBuf : std::streambuf {
  int overflow(int) override { return traits_type::eof(); }
  std::streamsize xsputn(const char*, std::streamsize) override { return 0; }
};
}  // namespace

TEST_CASE("session: an exception in a helper thread is an orderly safe stop with exit 70, not terminate",
          "[session][hardening]") {
  RtConfig cfg;
  auto backend = make_backend("sim", cfg);
  const std::string path = temp_path("internal.lcm");
  std::filesystem::remove(path);
  std::atomic<bool> interrupt{true};  // the supervisor writes its message at once...
  FailingBuf buf;
  std::ostream out(&buf);
  out.exceptions(std::ios::badbit);  // ...and that write throws
  RunOptions opt;
  opt.log_path = path;
  opt.lcm_url = "none";
  opt.quiet = true;
  opt.interrupt = &interrupt;
  const RunReport rep = run_session(cfg, *backend, opt, out);
  INFO(rep.message);
  CHECK(rep.exit_code == manip::exit_code::kInternal);
  CHECK(rep.message.find("supervisor") != std::string::npos);
  // the safe stop happened and the log is complete: gapless, ends in STOPPED
  manip::logging::EventLogReader rd(path);
  manip::logging::RawEvent ev;
  std::int64_t last = -1, gaps = 0, stopped_tail = 0;
  while (rd.next(ev)) {
    if (ev.channel != "MANIP_STATE") continue;
    manip::state_t s;
    REQUIRE(manip::logging::decode(ev, s));
    if (last >= 0 && s.cycle != last + 1) ++gaps;
    last = s.cycle;
    stopped_tail = s.mode == manip::state_t::MODE_STOPPED ? stopped_tail + 1 : 0;
  }
  CHECK(gaps == 0);
  CHECK(stopped_tail >= cfg.safety.shutdown_cycles);
  std::filesystem::remove(path);
}
