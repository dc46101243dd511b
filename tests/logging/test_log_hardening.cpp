// Damaged logs: corrupted length fields, garbage with fake event magics,
// string lengths <= 0, and the reader's allocation bound. Every corrupted log
// is built here from a good one, and what must be recovered is computed from
// the good log's own event list (an independent header walk below), not from
// the reader's earlier output.
#include <catch2/catch.hpp>

#include <algorithm>
#include <climits>
#include <cstdint>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

#include "fixtures.hpp"
#include "manip/command_status_t.hpp"
#include "manip/command_t.hpp"
#include "manip/common/channels.hpp"
#include "manip/estimation/trial_data.hpp"
#include "manip/health_t.hpp"
#include "manip/logging/safe_decode.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"

using namespace manip;
using Bytes = std::vector<std::uint8_t>;

namespace {

Bytes slurp_bytes(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}
void spit(const std::string& p, const Bytes& b) {
  std::ofstream out(p, std::ios::binary);
  out.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
}
std::uint32_t rd32(const Bytes& b, std::size_t at) {
  return (std::uint32_t(b[at]) << 24) | (std::uint32_t(b[at + 1]) << 16) | (std::uint32_t(b[at + 2]) << 8) |
         std::uint32_t(b[at + 3]);
}
void wr32(Bytes& b, std::size_t at, std::uint32_t v) {
  b[at] = std::uint8_t(v >> 24);
  b[at + 1] = std::uint8_t(v >> 16);
  b[at + 2] = std::uint8_t(v >> 8);
  b[at + 3] = std::uint8_t(v);
}

// The events of a *good* log by walking the headers (LCM layout: magic, i64
// event number, i64 utime, i32 channel length, i32 data length).
struct Ev {
  std::size_t off, data_off, data_len, total;
  std::string channel;
};
std::vector<Ev> index_events(const Bytes& b) {
  std::vector<Ev> out;
  std::size_t at = 0;
  while (at + 28 <= b.size()) {
    REQUIRE(rd32(b, at) == 0xEDA1DA01u);
    const std::size_t cl = rd32(b, at + 20), dl = rd32(b, at + 24);
    out.push_back({at, at + 28 + cl, dl, 28 + cl + dl, std::string(b.begin() + long(at + 28), b.begin() + long(at + 28 + cl))});
    at += 28 + cl + dl;
  }
  REQUIRE(at == b.size());
  return out;
}

// What a handler saw, in order: one string per message.
struct Seen final : logging::SessionHandler {
  std::vector<std::string> msgs;
  std::vector<std::string> warnings;
  void on_session(const manip::session_t&) override { msgs.push_back("session"); }
  void on_state(const manip::state_t& s) override { msgs.push_back("state " + std::to_string(s.cycle)); }
  void on_trial_event(const manip::trial_event_t& e) override {
    msgs.push_back("event " + std::to_string(e.trial) + "/" + std::to_string(e.kind));
  }
  void on_truth_state(const manip::state_t& s) override { msgs.push_back("twin " + std::to_string(s.cycle)); }
  void on_truth_impedance(const manip::impedance_truth_t& t) override {
    msgs.push_back("truth " + std::to_string(t.trial));
  }
  void on_fault(const manip::fault_t& f) override { msgs.push_back("fault " + std::to_string(f.cycle)); }
  void on_warning(const std::string& m) override { warnings.push_back(m); }
};

const std::string& hardening_good_log() {
  static const std::string path = testutil::write_small_good_log("log_hardening");
  return path;
}

// The good log's messages minus those listed (by index into its event list).
std::vector<std::string> expected_without(const std::vector<std::size_t>& removed) {
  Seen all;
  logging::read_log(hardening_good_log(), all);
  REQUIRE(all.warnings.empty());
  const auto evs = index_events(slurp_bytes(hardening_good_log()));
  REQUIRE(all.msgs.size() == evs.size());  // every event of the good log is a session/state/trial message
  std::vector<std::string> out;
  for (std::size_t i = 0; i < evs.size(); ++i)
    if (std::find(removed.begin(), removed.end(), i) == removed.end()) out.push_back(all.msgs[i]);
  return out;
}

std::size_t middle_event_on(const std::vector<Ev>& evs, std::string_view channel) {
  for (std::size_t i = evs.size() / 2; i < evs.size(); ++i)
    if (evs[i].channel == channel) return i;
  FAIL("no event on " << channel);
  return 0;
}

bool any_warning_with(const std::vector<std::string>& w, const std::string& a, const std::string& b) {
  return std::any_of(w.begin(), w.end(), [&](const std::string& s) {
    return s.find(a) != std::string::npos && s.find(b) != std::string::npos;
  });
}

}  // namespace

TEST_CASE("log hardening: one flipped bit in a data length loses that event only, not the rest of the log") {
  const Bytes good = slurp_bytes(hardening_good_log());
  const auto evs = index_events(good);
  // An event a quarter into the file, so that +8 MiB still lands inside it.
  std::size_t k = evs.size() / 4;
  while (evs[k].channel != channels::kState) ++k;
  REQUIRE(good.size() - evs[k].off > (std::size_t{9} << 20));
  const auto expected = expected_without({k});
  const auto dir = testutil::temp_dir("flipbit");

  // state_t payload is 162 bytes: bit 1 shortens it, the others lengthen it
  // (inside the event, inside the file, past the end, past the 256 MiB cap).
  for (const int bit : {1, 3, 12, 23, 27, 30}) {
    CAPTURE(bit);
    Bytes bad = good;
    wr32(bad, evs[k].off + 24, rd32(bad, evs[k].off + 24) ^ (1u << bit));
    const std::string path = dir + "/flip" + std::to_string(bit) + ".lcm";
    spit(path, bad);
    Seen seen;
    const auto sum = logging::read_log(path, seen);
    CHECK(seen.msgs == expected);
    CHECK_FALSE(sum.diagnostics.truncated_tail);
    // The damaged event is reported with the file and its offset.
    CHECK(any_warning_with(seen.warnings, path, "byte " + std::to_string(evs[k].off)));
    // Never more than the damaged event's own bytes are skipped.
    CHECK(sum.diagnostics.bytes_skipped > 0);
    CHECK(sum.diagnostics.bytes_skipped <= evs[k].total);
  }
}

TEST_CASE("log hardening: garbage with a fake event magic between events is skipped exactly, nothing else lost") {
  const Bytes good = slurp_bytes(hardening_good_log());
  const auto evs = index_events(good);
  const std::size_t k = middle_event_on(evs, channels::kTrial);
  const std::size_t at = evs[k].off;  // insert just before a trial event
  const auto expected = expected_without({});
  const auto dir = testutil::temp_dir("fakemagic");

  struct Case {
    const char* name;
    std::uint32_t chan_len, data_len;
  };
  // A fake header whose lengths fit in the file but whose end is not an event;
  // one claiming far more than the file holds (the false "last event
  // truncated" that dropped the rest of the log); one copying a real header.
  for (const Case c : {Case{"fits", 11, 5000}, Case{"past_eof", 11, 200u << 20}, 
                     Case{"real_header", static_cast<std::uint32_t>(evs[k].channel.size()),
                          static_cast<std::uint32_t>(evs[k].data_len)}}) {
    CAPTURE(c.name);
    Bytes garbage(300, 0x5a);
    wr32(garbage, 40, 0xEDA1DA01u);
    wr32(garbage, 40 + 20, c.chan_len);
    wr32(garbage, 40 + 24, c.data_len);
    std::copy(evs[k].channel.begin(), evs[k].channel.end(), garbage.begin() + 40 + 28);
    Bytes bad = good;
    bad.insert(bad.begin() + long(at), garbage.begin(), garbage.end());
    const std::string path = dir + "/" + c.name + ".lcm";
    spit(path, bad);
    Seen seen;
    const auto sum = logging::read_log(path, seen);
    CHECK(seen.msgs == expected);
    CHECK_FALSE(sum.diagnostics.truncated_tail);
    CHECK(sum.diagnostics.bytes_skipped == garbage.size());
    REQUIRE(sum.diagnostics.skipped.size() == 1);
    CHECK(sum.diagnostics.skipped[0].offset == at);
    CHECK(any_warning_with(seen.warnings, path, "skipped 300 bytes at byte " + std::to_string(at)));
  }
}

TEST_CASE("log hardening: a truncated last event is still reported as such, after garbage too") {
  Bytes bad = slurp_bytes(hardening_good_log());
  const auto evs = index_events(bad);
  bad.resize(evs.back().off + 40);  // cut inside the last event
  const auto dir = testutil::temp_dir("trunc2");
  spit(dir + "/t.lcm", bad);
  Seen seen;
  const auto sum = logging::read_log(dir + "/t.lcm", seen);
  CHECK(sum.diagnostics.truncated_tail);
  CHECK(sum.diagnostics.truncated_offset == evs.back().off);
  CHECK(sum.diagnostics.bytes_skipped == 0);
  CHECK(seen.msgs == expected_without({evs.size() - 1}));
}

TEST_CASE("log hardening: the reader never allocates for a length it has not verified") {
  const Bytes good = slurp_bytes(hardening_good_log());
  const auto evs = index_events(good);
  const std::size_t k = middle_event_on(evs, channels::kState);
  const auto dir = testutil::temp_dir("alloc");
  using R = logging::EventLogReader;

  SECTION("a declared 8 MiB or 256 MiB data length keeps the buffer at its minimum") {
    for (const std::uint32_t len : {std::uint32_t{8} << 20, (std::uint32_t{256} << 20) - 1}) {
      Bytes bad = good;
      wr32(bad, evs[k].off + 24, len);
      spit(dir + "/big.lcm", bad);
      R r(dir + "/big.lcm");
      logging::RawEvent ev;
      std::size_t n = 0;
      while (r.next(ev)) ++n;
      CHECK(n == evs.size() - 1);
      CHECK(r.buffer_bytes() == R::kMinBufferBytes);
      CHECK(r.diagnostics().largest_event_bytes == [&] {
        std::size_t m = 0;
        for (std::size_t i = 0; i < evs.size(); ++i)
          if (i != k) m = std::max(m, evs[i].total);
        return m;
      }());
    }
  }
  SECTION("a genuine 5 MiB event is read whole, with a buffer of that size plus the read-ahead") {
    Bytes big;
    const std::string ch = "OTHER_TOOL_BLOB";
    const std::size_t dl = std::size_t{5} << 20;
    big.resize(28 + ch.size() + dl, 0xEE);
    wr32(big, 0, 0xEDA1DA01u);
    std::fill(big.begin() + 4, big.begin() + 20, 0);
    wr32(big, 20, std::uint32_t(ch.size()));
    wr32(big, 24, std::uint32_t(dl));
    std::copy(ch.begin(), ch.end(), big.begin() + 28);
    Bytes log = good;
    log.insert(log.begin() + long(evs[k].off), big.begin(), big.end());
    spit(dir + "/blob.lcm", log);
    R r(dir + "/blob.lcm");
    logging::RawEvent ev;
    std::size_t n = 0, blob = 0;
    while (r.next(ev)) {
      ++n;
      if (ev.channel == ch) blob = ev.data.size();
    }
    CHECK(n == evs.size() + 1);
    CHECK(blob == dl);
    CHECK(r.diagnostics().bytes_skipped == 0);
    CHECK(r.buffer_bytes() == big.size() + R::kReadAheadBytes);
  }
}

TEST_CASE("log hardening: string length <= 0 in a trial or session event is a warning naming file, offset, channel") {
  const Bytes good = slurp_bytes(hardening_good_log());
  const auto evs = index_events(good);
  const auto dir = testutil::temp_dir("strlen");
  // trial_event_t payload: 8-byte fingerprint, 78 bytes of fixed fields, then
  // the i32 length of `reason` (lcmtypes/trial_event_t.lcm).
  const std::size_t k = middle_event_on(evs, channels::kTrial);
  for (const std::int32_t len : {0, -1, INT_MIN, 1 << 30}) {
    CAPTURE(len);
    Bytes bad = good;
    wr32(bad, evs[k].data_off + 86, static_cast<std::uint32_t>(len));
    const std::string path = dir + "/trial.lcm";
    spit(path, bad);
    Seen seen;
    const auto sum = logging::read_log(path, seen);
    CHECK(seen.msgs == expected_without({k}));
    CHECK(sum.undecodable == 1);
    CHECK(any_warning_with(seen.warnings, path + ": byte " + std::to_string(evs[k].off) + " (MANIP_TRIAL)",
                           "string length " + std::to_string(len)));
  }
  SECTION("in the session message: the rest of the log is read, and the assembler's error names file and cause") {
    REQUIRE(evs[0].channel == channels::kSession);
    Bytes bad = good;
    wr32(bad, evs[0].data_off + 8 + 4, 0);  // software_version length (after schema_version)
    const std::string path = dir + "/session.lcm";
    spit(path, bad);
    Seen seen;
    logging::read_log(path, seen);
    CHECK(seen.msgs == expected_without({0}));
    CHECK(any_warning_with(seen.warnings, path + ": byte 0 (MANIP_SESSION)", "string length 0"));
    estimation::TrialAssembler asmb([](const estimation::SessionInfo&, estimation::TrialData&&) {});
    CHECK_THROWS_WITH(logging::read_log(path, asmb),
                      Catch::Contains(path) && Catch::Contains("(MANIP_TRIAL)") && Catch::Contains("no session message") &&
                          Catch::Contains("session message at byte 0 was damaged"));
  }
}

TEST_CASE("log hardening: a log without a session message is refused naming the file and the byte") {
  auto d = testutil::small_design(9);
  d.write_twins = false;
  const auto rec = testutil::record(d, sim::table1_person());
  const auto dir = testutil::temp_dir("nosession2");
  testutil::write_recorded(rec, dir + "/n.lcm", false);
  estimation::TrialAssembler asmb([](const estimation::SessionInfo&, estimation::TrialData&&) {});
  CHECK_THROWS_WITH(logging::read_log(dir + "/n.lcm", asmb),
                    Catch::Contains(dir + "/n.lcm: byte ") && Catch::Contains("no session message"));
}

// ---- safe_decode on its own -------------------------------------------------

namespace {
template <class Msg>
Bytes encode(const Msg& m) {
  Bytes b(static_cast<std::size_t>(m.getEncodedSize()));
  REQUIRE(m.encode(b.data(), 0, static_cast<int>(b.size())) == static_cast<int>(b.size()));
  return b;
}
manip::fault_t sample_fault() {
  manip::fault_t f{};
  f.cycle = 77;
  f.reason = "workspace: axis 1";
  f.n_history = 3;
  f.history.resize(3);
  for (int i = 0; i < 3; ++i) f.history[static_cast<std::size_t>(i)].cycle = 75 + i;
  return f;
}
manip::session_t sample_session() {
  manip::session_t s{};
  s.schema_version = 1;
  s.software_version = "0.1.0";
  s.source = "test";
  s.participant_id = "P";
  s.session_id = "";
  s.sample_rate_hz = 4000;
  s.config_yaml = "a: 1\n";
  return s;
}
}  // namespace

TEST_CASE("safe_decode: every type round-trips and its wire walk covers exactly the encoded bytes") {
  // The walk's layouts are hand-written per type (src/logging/safe_decode.cpp):
  // these round trips fail as soon as one drifts from the generated code.
  manip::trial_event_t e{};
  e.cycle = 12345;
  e.reason = "timeout";
  manip::trial_event_t e2;
  REQUIRE(logging::safe_decode(encode(e), e2).ok());
  CHECK(e2.cycle == 12345);
  CHECK(e2.reason == "timeout");

  manip::fault_t f2;
  REQUIRE(logging::safe_decode(encode(sample_fault()), f2).ok());
  CHECK(f2.history.size() == 3);
  CHECK(f2.history[2].cycle == 77);

  manip::session_t s2;
  REQUIRE(logging::safe_decode(encode(sample_session()), s2).ok());
  CHECK(s2.config_yaml == "a: 1\n");

  manip::state_t st{}, st2;
  st.cycle = 9;
  REQUIRE(logging::safe_decode(encode(st), st2).ok());
  manip::impedance_truth_t t{}, t2;
  t.model = "linear";
  REQUIRE(logging::safe_decode(encode(t), t2).ok());
  manip::health_t h{}, h2;
  REQUIRE(logging::safe_decode(encode(h), h2).ok());
  manip::command_t c{}, c2;
  c.sender = "gui";
  c.kind = 5;
  REQUIRE(logging::safe_decode(encode(c), c2).ok());
  CHECK(c2.sender == "gui");
  manip::command_status_t cs{}, cs2;
  cs.reason = "no";
  REQUIRE(logging::safe_decode(encode(cs), cs2).ok());
  CHECK(cs2.reason == "no");

  // Another type's bytes are refused by fingerprint.
  CHECK(logging::safe_decode(encode(e), st2).status == logging::DecodeStatus::wrong_type);
}

TEST_CASE("safe_decode: bad string lengths and array counts are refused before the generated decode runs") {
  using logging::DecodeStatus;
  SECTION("string lengths") {
    manip::command_t c{};
    c.sender = "gui";
    const Bytes good = encode(c);
    // command_t: fingerprint 8, utime 8, seq 8, then the sender's i32 length.
    // 5 instead of 4 ("gui" + NUL) shifts the fields after it: the payload
    // then ends inside the last field.
    for (const std::int32_t len : {0, -1, -2, INT_MIN, 5, INT_MAX}) {
      CAPTURE(len);
      Bytes bad = good;
      wr32(bad, 24, static_cast<std::uint32_t>(len));
      manip::command_t out;
      const auto r = logging::safe_decode(bad.data(), bad.size(), out);
      CHECK(r.status == (len == 5 ? DecodeStatus::short_data : DecodeStatus::bad_string_length));
      if (len != 5) {
        CHECK(r.at == 24);
        CHECK(r.value == len);
      }
    }
  }
  SECTION("array count of fault_t.history") {
    const Bytes good = encode(sample_fault());
    // fault_t: fingerprint 8, utime 8, cycle 8, flags 4, reason (4 + 18), n_history.
    const std::size_t at = 8 + 8 + 8 + 4 + 4 + 18;
    REQUIRE(rd32(good, at) == 3);
    for (const std::int32_t n : {-1, INT_MIN, 4, 1 << 24, INT_MAX}) {
      CAPTURE(n);
      Bytes bad = good;
      wr32(bad, at, static_cast<std::uint32_t>(n));
      manip::fault_t out;
      const auto r = logging::safe_decode(bad, out);
      CHECK(r.status == DecodeStatus::bad_array_length);
      CHECK(r.at == at);
      CHECK(out.history.size() <= 3);  // nothing sized from the bad count
    }
  }
  SECTION("every truncation and random corruption: never ok when damaged, never throws") {
    const Bytes good = encode(sample_session());
    for (std::size_t n = 0; n < good.size(); ++n) {
      manip::session_t out;
      CHECK_FALSE(logging::safe_decode(std::span<const std::uint8_t>(good.data(), n), out).ok());
    }
    std::mt19937 rng(3);
    std::size_t ok = 0;
    for (int trial = 0; trial < 20000; ++trial) {
      Bytes bad = good;
      for (int j = 0; j < 3; ++j) bad[8 + rng() % (bad.size() - 8)] = static_cast<std::uint8_t>(rng());
      manip::session_t out;
      ok += logging::safe_decode(bad, out).ok() ? 1 : 0;
    }
    CHECK(ok < 20000);  // corrupting the doubles still decodes; the point is that nothing threw
  }
}

TEST_CASE("log hardening: zeros after the last event (a preallocated file) are skipped garbage, not a truncated event") {
  Bytes bad = slurp_bytes(hardening_good_log());
  const auto evs = index_events(bad);
  const std::size_t size = bad.size();
  bad.resize(size + 4096, 0);
  const auto dir = testutil::temp_dir("zeros");
  spit(dir + "/z.lcm", bad);
  Seen seen;
  const auto sum = logging::read_log(dir + "/z.lcm", seen);
  CHECK(seen.msgs == expected_without({}));
  CHECK_FALSE(sum.diagnostics.truncated_tail);
  REQUIRE(sum.diagnostics.skipped.size() == 1);
  CHECK(sum.diagnostics.skipped[0].offset == size);
  CHECK(sum.diagnostics.skipped[0].bytes == 4096);
  CHECK(any_warning_with(seen.warnings, dir + "/z.lcm", "skipped 4096 bytes at byte " + std::to_string(size)));
  CHECK(evs.back().off + evs.back().total == size);
}
