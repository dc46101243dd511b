// The event-log reader against the stock lcm::LogFile, and on every bad input.
#include <catch2/catch.hpp>

#include <lcm/lcm-cpp.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>

#include "fixtures.hpp"
#include "manip/common/channels.hpp"
#include "manip/estimation/session_estimator.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"

using namespace manip;

namespace {
std::vector<char> slurp(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}
void spit(const std::string& p, const std::vector<char>& b) {
  std::ofstream out(p, std::ios::binary);
  out.write(b.data(), static_cast<std::streamsize>(b.size()));
}
struct Counter final : logging::SessionHandler {
  int sessions = 0, states = 0, events = 0;
  std::vector<std::string> warnings;
  void on_session(const manip::session_t&) override { ++sessions; }
  void on_state(const manip::state_t&) override { ++states; }
  void on_trial_event(const manip::trial_event_t&) override { ++events; }
  void on_warning(const std::string& m) override { warnings.push_back(m); }
};
const std::string& good_log() {
  static const std::string path = testutil::write_small_good_log("event_log");
  return path;
}
}  // namespace

TEST_CASE("event log: our reader and lcm::LogFile see the same events") {
  lcm::LogFile stock(good_log(), "r");
  REQUIRE(stock.good());
  logging::EventLogReader ours(good_log());
  logging::RawEvent ev;
  std::size_t n = 0, mismatches = 0;
  while (const lcm::LogEvent* s = stock.readNextEvent()) {
    REQUIRE(ours.next(ev));
    const bool same = ev.event_number == s->eventnum && ev.utime == s->timestamp && ev.channel == s->channel &&
                      ev.data.size() == static_cast<std::size_t>(s->datalen) &&
                      std::equal(ev.data.begin(), ev.data.end(), static_cast<const std::uint8_t*>(s->data));
    if (!same) ++mismatches;
    ++n;
  }
  CHECK(mismatches == 0);
  CHECK_FALSE(ours.next(ev));
  CHECK(n > 10000);
  CHECK(ours.diagnostics().bytes_skipped == 0);
  CHECK_FALSE(ours.diagnostics().truncated_tail);
}

TEST_CASE("event log: missing file and non-LCM file are refused with the file named") {
  CHECK_THROWS_WITH(logging::EventLogReader("/nonexistent/x.lcm"), Catch::Contains("/nonexistent/x.lcm"));
  const auto dir = testutil::temp_dir("notlcm");
  spit(dir + "/x.lcm", std::vector<char>(1000, 'a'));
  CHECK_THROWS_WITH(logging::EventLogReader(dir + "/x.lcm"), Catch::Contains("not an LCM event log"));
}

TEST_CASE("event log: garbage in the middle is skipped, reported with its offset, and the rest is read") {
  auto bytes = slurp(good_log());
  const std::size_t at = bytes.size() / 2;
  std::vector<char> garbage(777, '\x5a');
  garbage[100] = '\xED';  // a stray magic prefix inside the garbage
  garbage[101] = '\xA1';
  bytes.insert(bytes.begin() + static_cast<std::ptrdiff_t>(at), garbage.begin(), garbage.end());
  const auto dir = testutil::temp_dir("garbage");
  spit(dir + "/g.lcm", bytes);
  Counter good, bad;
  logging::read_log(good_log(), good);
  const auto sum = logging::read_log(dir + "/g.lcm", bad);
  // At most the one event the garbage was inserted into is lost.
  CHECK(bad.states + bad.events >= good.states + good.events - 1);
  CHECK(sum.diagnostics.bytes_skipped >= 777);
  CHECK(sum.diagnostics.bytes_skipped < 777 + 400);
  REQUIRE_FALSE(bad.warnings.empty());
  CHECK_THAT(bad.warnings.front(), Catch::Contains("skipped") && Catch::Contains("at byte"));
}

TEST_CASE("event log: a truncated last event is reported and everything before it is read") {
  auto bytes = slurp(good_log());
  // erase, not resize: GCC 12 -O3 + ASan warns (falsely) that resize may memset 2^64 bytes.
  bytes.erase(bytes.end() - 50, bytes.end());
  const auto dir = testutil::temp_dir("trunc");
  spit(dir + "/t.lcm", bytes);
  Counter good, cut;
  logging::read_log(good_log(), good);
  const auto sum = logging::read_log(dir + "/t.lcm", cut);
  CHECK(sum.diagnostics.truncated_tail);
  CHECK(cut.states + cut.events == good.states + good.events - 1);
  CHECK_THAT(cut.warnings.back(), Catch::Contains("truncated"));
}

TEST_CASE("event log: a session message of another schema version is refused naming both versions") {
  auto d = testutil::small_design(9);
  d.write_twins = false;
  auto rec = testutil::record(d, sim::table1_person());
  rec.session.schema_version = 7;
  const auto dir = testutil::temp_dir("schema");
  testutil::write_recorded(rec, dir + "/v7.lcm");
  Counter c;
  CHECK_THROWS_WITH(logging::read_log(dir + "/v7.lcm", c), Catch::Contains("version 7") && Catch::Contains("version 1"));
}

TEST_CASE("estimation input checks: no session, gaps, NaN, missing onset, short trial") {
  auto d = testutil::small_design(10);
  d.write_twins = false;
  const auto rec = testutil::record(d, sim::table1_person());
  const auto dir = testutil::temp_dir("badinput");
  estimation::EstimatorSettings s;

  SECTION("no session message") {
    testutil::write_recorded(rec, dir + "/nosession.lcm", false);
    CHECK_THROWS_WITH(estimation::estimate_log(dir + "/nosession.lcm", s), Catch::Contains("session"));
  }
  // Find the perturbed trials and tamper with some of them.
  std::vector<int> perturbed;
  for (const auto& it : rec.items)
    if (it.kind == 1 && it.event.kind == manip::trial_event_t::ONSET) perturbed.push_back(it.event.trial);
  REQUIRE(perturbed.size() == 8);
  auto tampered = rec;
  tampered.items.clear();
  bool dropped_gap = false;
  int nan_done = 0;
  for (auto it : rec.items) {
    if (it.kind == 0 && it.state.trial == perturbed[0] && !dropped_gap && it.state.cycle % 1000 == 500) {
      dropped_gap = true;  // a gap in the cycle counter
      continue;
    }
    if (it.kind == 0 && it.state.trial == perturbed[1] && nan_done++ == 3000) it.state.x_workspace_m[1] = NAN;
    if (it.kind == 1 && it.event.kind == manip::trial_event_t::ONSET && it.event.trial == perturbed[2]) continue;
    tampered.items.push_back(it);
  }
  testutil::write_recorded(tampered, dir + "/tampered.lcm");
  const auto r = estimation::estimate_log(dir + "/tampered.lcm", s);
  auto issue_for = [&](int trial) {
    for (const auto& i : r.issues)
      if (i.trial == trial) return i.reason;
    return std::string();
  };
  CHECK_THAT(issue_for(perturbed[0]), Catch::Contains("gap in the cycle counter"));
  CHECK_THAT(issue_for(perturbed[1]), Catch::Contains("non-finite"));
  CHECK_THAT(issue_for(perturbed[2]), Catch::Contains("without a perturbation onset"));
  CHECK(r.n_used == 5);  // every good perturbed trial is still estimated
  bool has_session_summary = false;
  for (const auto& sm : r.summaries) has_session_summary = has_session_summary || sm.group.is_session();
  CHECK(has_session_summary);

  SECTION("a window longer than the trials names the trial") {
    estimation::EstimatorSettings longw;
    longw.pipeline.t_est_s = longw.oe.t_est_s = 2.5;
    const auto r2 = estimation::estimate_log(dir + "/tampered.lcm", longw);
    CHECK(r2.n_used == 0);
    bool named = false;
    for (const auto& i : r2.issues) named = named || i.reason.find("shorter than") != std::string::npos ||
                                               i.reason.find("ends before") != std::string::npos;
    CHECK(named);
  }
}
