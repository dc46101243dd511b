// Bad-input matrix of the estimate_impedance executable (issue 9 item 6,
// issue 13): every bad input gets its documented exit code and a one-line
// message naming the file (and field, option, trial or byte offset), bad
// options are refused before any log is read, and a good log on the same
// command line is still estimated. The observed table is in
// docs/reliability.md ("Bad input: estimate_impedance").
#include <catch2/catch.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <sstream>

#include "fixtures.hpp"
#include "manip/common/channels.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/logging/event_log.hpp"
#include "manip/sim/presets.hpp"
#include "synthetic.hpp"

using namespace manip;
namespace ec = manip::exit_code;

namespace {

const std::string kEstimateApp = std::string(MANIP_BINARY_DIR) + "/apps/estimate_impedance";

struct Result {
  int code{-1};
  std::string out, err;
};

std::string slurp(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream os;
  os << in.rdbuf();
  return os.str();
}

Result run(const std::string& args, const std::string& env = "") {
  const auto base = std::filesystem::temp_directory_path() / ("bad_input_matrix_" + std::to_string(::getpid()));
  const std::string o = base.string() + ".out", e = base.string() + ".err";
  const int st = std::system((env + " " + kEstimateApp + " " + args + " >" + o + " 2>" + e).c_str());
  Result r{WIFEXITED(st) ? WEXITSTATUS(st) : -1, slurp(o), slurp(e)};
  std::filesystem::remove(o);
  std::filesystem::remove(e);
  return r;
}

template <class T>
std::vector<std::uint8_t> encode(const T& m) {
  std::vector<std::uint8_t> b(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(b.data(), 0, static_cast<int>(b.size()));
  return b;
}

// Writes a recorded session event by event, letting the case tamper with
// each encoded event (channel, bytes) or drop/add events.
using Tamper = std::function<void(std::string& channel, std::vector<std::uint8_t>& bytes, std::size_t index, bool& keep)>;

void write_raw(const testutil::Recorded& r, const std::string& path, const Tamper& tamper = {}) {
  logging::EventLogWriter w;
  REQUIRE(w.open(path));
  std::int64_t utime = 1'000'000;
  bool ok = true;
  auto put = [&](std::string ch, std::vector<std::uint8_t> b, std::size_t i) {
    bool keep = true;
    if (tamper) tamper(ch, b, i, keep);
    if (keep) ok = w.write(ch, utime, b) && ok;
  };
  put(channels::kSession, encode(r.session), 0);
  std::size_t i = 1;
  for (const auto& it : r.items) {
    switch (it.kind) {
      case 0: utime = it.state.utime; put(channels::kState, encode(it.state), i); break;
      case 1: put(channels::kTrial, encode(it.event), i); break;
      case 2: put(channels::kTruthState, encode(it.state), i); break;
      default: put(channels::kTruthImpedance, encode(it.truth), i);
    }
    ++i;
  }
  REQUIRE(ok);
  w.close();
}

bool has(const std::string& text, const std::string& what) { return text.find(what) != std::string::npos; }

// The good log's results are on stdout: its header and the Table-1 summary.
bool good_estimated(const Result& r, const std::string& good) {
  return has(r.out, "manip estimate_impedance: " + good + "\n") && has(r.out, "session damping D [N s/m]");
}

}  // namespace

TEST_CASE("estimate_impedance bad-input matrix", "[cli][bad_input]") {
  if (!std::filesystem::exists(kEstimateApp)) {
    WARN("estimate_impedance not built: skipped (ninja estimate_impedance)");
    return;
  }
  const auto dir = testutil::temp_dir("bad_input_matrix");
  const auto rec = testutil::record(testutil::small_design(10), sim::table1_person());
  const std::string good = dir + "/good.lcm";
  write_raw(rec, good);
  const std::string opts = " -q --method paper-pooled ";

  SECTION("a good log alone: estimated") {
    const auto r = run(good + opts);
    CHECK(r.code <= ec::kPartial);
    CHECK(good_estimated(r, good));
  }
  SECTION("missing log before a good one: exit 4 naming it, the good log estimated") {
    const auto r = run(dir + "/missing.lcm " + good + opts);
    CHECK(r.code == ec::kInput);
    CHECK(has(r.err, dir + "/missing.lcm: cannot open"));
    CHECK(good_estimated(r, good));
  }
  SECTION("bad option values: exit 2 naming the option, before any log is read") {
    for (const std::string bad : {"--cutoff abc", "--cutoff 2000", "--cutoff -1", "--cutoff 0", "--cutoff nan",
                                  "--sg-window 3", "--sg-window 8", "--sg-window -225", "--sg-window x",
                                  "--t-est nan", "--t-est -0.1", "--t-est 5", "--t-est 0.15s", "--cutoff-threshold-db inf",
                                  "--oe-pre -1", "--oe-poly-order 99", "--k-model cubic", "--force-source none",
                                  "--position-source stage"}) {
      INFO(bad);
      const auto r = run(good + opts + bad);
      CHECK(r.code == ec::kUsage);
      CHECK(has(r.err, bad.substr(0, bad.find(' '))));
      CHECK_FALSE(has(r.err, "stod"));
      CHECK(r.out.empty());  // nothing estimated: refused before reading
    }
  }
  SECTION("session message with NaN or negative m_adm, absurd sample rate: exit 4 naming file and field") {
    struct Case {
      const char* name;
      std::function<void(session_t&)> f;
      const char* field;
    };
    const std::vector<Case> cases{
        {"nan_madm", [](session_t& s) { s.m_adm_kg[0] = std::numeric_limits<double>::quiet_NaN(); }, "m_adm_kg"},
        {"neg_madm", [](session_t& s) { s.m_adm_kg[1] = -2.0; }, "m_adm_kg"},
        {"rate_absurd", [](session_t& s) { s.sample_rate_hz = 1e9; }, "sample_rate_hz"},
        {"rate_zero", [](session_t& s) { s.sample_rate_hz = 0; }, "sample_rate_hz"}};
    for (const auto& c : cases) {
      INFO(c.name);
      auto bad = rec;
      c.f(bad.session);
      const std::string p = dir + "/" + c.name + ".lcm";
      write_raw(bad, p);
      const auto r = run(p + " " + good + opts);
      CHECK(r.code == ec::kInput);
      CHECK(has(r.err, p + ": "));
      CHECK(has(r.err, c.field));
      CHECK(good_estimated(r, good));
    }
  }
  SECTION("not an LCM log (garbage), empty file: exit 4 naming the file") {
    const std::string g = dir + "/garbage.lcm", e = dir + "/empty.lcm";
    {
      std::ofstream o(g, std::ios::binary);
      for (int i = 0; i < 5000; ++i) o.put(static_cast<char>((i * 7919) & 0xff));
    }
    std::ofstream(e).close();
    for (const auto& p : {g, e}) {
      INFO(p);
      const auto r = run(p + " " + good + opts);
      CHECK(r.code == ec::kInput);
      CHECK(has(r.err, p + ": "));
      CHECK(good_estimated(r, good));
    }
  }
  SECTION("truncated log: the damage reported with the byte offset, the complete trials estimated") {
    const std::string t = dir + "/truncated.lcm";
    const std::string bytes = slurp(good);
    std::ofstream(t, std::ios::binary) << bytes.substr(0, bytes.size() * 2 / 3 + 17);
    const auto r = run(t + " " + good + opts);
    CHECK(r.code <= ec::kPartial);
    CHECK(has(r.err, "estimate_impedance: " + t + ": last event at byte "));
    CHECK_FALSE(has(r.err, t + ": " + t));  // the file named once
    CHECK(good_estimated(r, t));
    CHECK(good_estimated(r, good));
  }
  SECTION("fake magic inside garbage in the middle: resynchronised, offsets reported, the rest not lost") {
    const std::string f = dir + "/fakemagic.lcm";
    std::string bytes = slurp(good);
    std::string junk(300, '\x5a');
    const unsigned char magic[4] = {0xED, 0xA1, 0xDA, 0x01};
    std::memcpy(junk.data() + 100, magic, 4);
    bytes.insert(bytes.size() / 2, junk);
    std::ofstream(f, std::ios::binary) << bytes;
    const auto r = run(f + " " + good + " -q --method paper-pooled --json " + dir + "/fm.json");
    CHECK(r.code <= ec::kPartial);
    CHECK(has(r.err, f + ": skipped 300 bytes at byte "));
    CHECK(good_estimated(r, f));
    // Nothing but the one damaged spot is lost: the same number of trials as the good log.
    const std::string js = slurp(dir + "/fm.json");
    CHECK(js.find("\"trials\": 10") != std::string::npos);
  }
  SECTION("zero-length string in a trial event: the event dropped with file, offset and channel, the log estimated") {
    const std::string z = dir + "/strlen0.lcm";
    auto r0 = rec;
    bool patched = false;
    for (auto& it : r0.items)
      if (it.kind == 1 && !patched) {
        it.event.reason = "ZZZZ";
        patched = true;
      }
    write_raw(r0, z, [](std::string& ch, std::vector<std::uint8_t>& b, std::size_t, bool&) {
      if (ch != channels::kTrial) return;
      for (std::size_t k = 4; k + 4 <= b.size(); ++k)
        if (std::memcmp(b.data() + k, "ZZZZ", 4) == 0) std::memset(b.data() + k - 4, 0, 4);  // length field 0
    });
    const auto r = run(z + " " + good + opts);
    CHECK(r.code <= ec::kPartial);
    CHECK(has(r.err, z + ": byte "));
    CHECK(has(r.err, "MANIP_TRIAL"));
    CHECK(good_estimated(r, z));
    CHECK(good_estimated(r, good));
  }
  SECTION("START after the trial's first state (third-party writer order): estimated as usual") {
    const std::string s = dir + "/start_late.lcm";
    auto r0 = rec;
    // Move every START one position later (after the first state of its trial).
    for (std::size_t i = 0; i + 1 < r0.items.size(); ++i)
      if (r0.items[i].kind == 1 && r0.items[i].event.kind == trial_event_t::START && r0.items[i + 1].kind == 0) {
        std::swap(r0.items[i], r0.items[i + 1]);
        ++i;
      }
    write_raw(r0, s);
    const auto r = run(s + " " + good + opts);
    CHECK(r.code <= ec::kPartial);
    CHECK_FALSE(has(r.err, "out of sequence"));
    CHECK(good_estimated(r, s));
    CHECK(good_estimated(r, good));
  }
  SECTION("live-bus recording (MANIP_STATE_LIVE at 250 Hz, no MANIP_STATE): named as such, exit 4") {
    const std::string l = dir + "/live.lcm";
    write_raw(rec, l, [](std::string& ch, std::vector<std::uint8_t>&, std::size_t i, bool& keep) {
      if (ch == channels::kState) {
        ch = channels::kStateLive;
        keep = i % 16 == 0;  // 4 kHz / 16 = 250 Hz, as manip_rt's live bus
      }
      if (ch == channels::kTruthState || ch == channels::kTruthImpedance) keep = false;
    });
    const auto r = run(l + " " + good + opts);
    CHECK(r.code == ec::kInput);
    CHECK(has(r.err, l + ": no MANIP_STATE (4 kHz) channel: this looks like a live-bus recording (MANIP_STATE_LIVE at 250 Hz"));
    CHECK(has(r.err, "record with manip_rt --out"));
    CHECK(good_estimated(r, good));
  }
  SECTION("a short log (session message, a few states, no trial): printed plainly, exit 5") {
    const std::string s = dir + "/short.lcm";
    auto r0 = rec;
    r0.session.session_id = "";
    r0.session.participant_id = "";
    r0.items.resize(20);
    for (auto& it : r0.items) it.kind = 0;
    write_raw(r0, s);
    const auto r = run(s + opts);
    CHECK(r.code == ec::kNothing);
    CHECK(has(r.out, "trials 0, perturbed 0, used 0"));
    CHECK(has(r.out, "session (not given), participant (not given)"));
    CHECK_FALSE(has(r.out, "nan"));
    CHECK(has(r.err, s + ": no usable perturbed trial"));
  }
  SECTION("--plots/--report without a usable Python: the estimate printed, one line naming it, exit 6, nothing left") {
    const std::string pd = dir + "/plots_nopy", rp = dir + "/nopy.html";
    const auto r = run(good + opts + "--plots " + pd + " --report " + rp, "MANIP_PYTHON=/nonexistent/python");
    CHECK(r.code == ec::kOutput);
    CHECK(good_estimated(r, good));
    CHECK(has(r.err, "--plots " + pd + ": not written: Python interpreter '/nonexistent/python' cannot be run"));
    CHECK_FALSE(std::filesystem::exists(rp));
    CHECK((!std::filesystem::exists(pd) || std::filesystem::is_empty(pd)));
  }
  SECTION("--plots and --report through python/manipplot (when the project venv exists)") {
    const std::string py = std::string(MANIP_SOURCE_DIR) + "/.venv/bin/python";
    if (!std::filesystem::exists(py)) {
      WARN("no .venv: skipped (scripts/setup.sh)");
      return;
    }
    const std::string pd = dir + "/plots", rp = dir + "/report.html";
    const auto r = run(good + opts + "--plots " + pd + " --report " + rp, "MANIP_PYTHON=" + py);
    CHECK(r.code <= ec::kPartial);
    for (const char* f : {"fig3_psd_jerk_x2.png", "fig3_psd_jerk_x2.pdf", "fig3_psd_jerk_x2.svg",
                          "directional_paper-pooled.png", "table1_paper-pooled.png"}) {
      INFO(f);
      CHECK(std::filesystem::exists(pd + "/" + f));
    }
    bool fig5 = false;
    for (const auto& e : std::filesystem::directory_iterator(pd)) fig5 = fig5 || e.path().filename().string().rfind("fig5_trial_", 0) == 0;
    CHECK(fig5);
    CHECK(has(slurp(rp), "<html"));
    // A second run without --force refuses, and leaves both untouched.
    const auto r2 = run(good + opts + "--report " + rp);
    CHECK(r2.code == ec::kOutput);
    CHECK(has(r2.err, rp + ": exists"));
  }
  SECTION("an existing output without --force: refused before reading, the file untouched") {
    const std::string j = dir + "/exists.json";
    std::ofstream(j) << "keep me\n";
    auto r = run(good + opts + "--json " + j);
    CHECK(r.code == ec::kOutput);
    CHECK(has(r.err, j));
    CHECK(r.out.empty());
    CHECK(slurp(j) == "keep me\n");
    r = run(good + opts + "--json " + j + " --force");
    CHECK(r.code <= ec::kPartial);
    CHECK(has(slurp(j), "\"default_method\": \"pem\""));
  }
}
