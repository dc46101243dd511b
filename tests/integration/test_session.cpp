// Whole manip_rt sessions on the sim backend (run_session: loop, logger and bus
// threads), checked from the log file they write.
#include <catch2/catch.hpp>

#include "../hardware/offline_run.hpp"
#include "../hardware/sanitized.hpp"

#include <sys/resource.h>

#include <chrono>
#include <csignal>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <sstream>

#include "manip/common/channels.hpp"
#include "manip/common/perturbation.hpp"
#include "manip/runtime/config.hpp"
#include "manip/common/errors.hpp"
#include "manip/hardware/backend.hpp"
#include "manip/runtime/backends.hpp"
#include "manip/runtime/session.hpp"
#include "manip/hardware/sim_backend.hpp"
#include "manip/logging/event_log.hpp"
#include "manip/session_t.hpp"
#include "manip/state_t.hpp"
#include "manip/trial_event_t.hpp"

using namespace manip::control;
using namespace manip::runtime;
namespace hw = manip::hardware;
namespace ec = manip::exit_code;
using manip::Vec2;

namespace {


std::string cfg_path() { return std::string(MANIP_SOURCE_DIR) + "/config/rt.yaml"; }
std::string tmp(const char* name) {
  return (std::filesystem::temp_directory_path() /
          (std::string("manip_rt_test_") + name + "_" + std::to_string(::getpid()) + ".lcm"))
      .string();
}
RtConfig shortened(int movements) {
  const RtConfig base = load_rt_config(cfg_path());
  return load_rt_config(cfg_path(), trials_overrides(base, movements));
}

struct LogContents {
  manip::session_t session{};
  bool session_first{false};
  std::vector<manip::state_t> states;
  std::vector<manip::trial_event_t> events;
  std::int64_t gaps{0};
  std::int64_t other{0};
};

// Reads the log; keeps all states only if keep_states (the full session has ~2 M).
LogContents read_log(const std::string& path, bool keep_states) {
  LogContents c;
  manip::logging::EventLogReader rd(path);
  manip::logging::RawEvent ev;
  bool first = true;
  std::int64_t last = -1;
  while (rd.next(ev)) {
    if (first) {
      c.session_first = ev.channel == manip::channels::kSession && manip::logging::decode(ev, c.session);
      first = false;
      continue;
    }
    if (ev.channel == manip::channels::kState) {
      manip::state_t s{};
      REQUIRE(manip::logging::decode(ev, s));
      if (last >= 0 && s.cycle != last + 1) ++c.gaps;
      if (last < 0 && s.cycle != 0) ++c.gaps;
      last = s.cycle;
      if (keep_states) c.states.push_back(s);
    } else if (ev.channel == manip::channels::kTrial) {
      manip::trial_event_t e{};
      REQUIRE(manip::logging::decode(ev, e));
      c.events.push_back(e);
    } else {
      ++c.other;
    }
  }
  return c;
}

RunReport run(const RtConfig& cfg, const std::string& log, std::ostringstream& out, RunOptions opt = {}) {
  const auto backend = make_backend("sim", cfg);
  REQUIRE(backend);
  opt.log_path = log;
  opt.overwrite_log = true;
  if (opt.lcm_url.empty()) opt.lcm_url = "none";
  opt.quiet = true;
  return run_session(cfg, *backend, opt, out);
}

}  // namespace

TEST_CASE("shortened session: log is complete, gapless, and the onsets are the first crossings", "[session]") {
  // 8 movements (2 perturbed); 1 perturbed movement under the sanitizers
  const RtConfig cfg = kSanitized ? load_rt_config(cfg_path(), {{"protocol.movements", "1"}, {"protocol.perturbed_trials", "1"}})
                                  : shortened(8);
  REQUIRE(cfg.perturbed_count() == (kSanitized ? 1 : 2));
  const std::string path = tmp("short");
  std::ostringstream out;
  const auto rep = run(cfg, path, out);
  INFO(out.str() << rep.summary());
  REQUIRE(rep.exit_code == ec::kOk);
  CHECK(rep.stop_reason == StopReason::kSessionDone);
  CHECK(rep.trials.completed == cfg.protocol.movements);
  CHECK(rep.trials.perturbed_completed == cfg.perturbed_count());
  CHECK(rep.log_drops == 0);
  CHECK(rep.log.missing_cycles == 0);

  const LogContents lc = read_log(path, true);
  REQUIRE(lc.session_first);
  const auto& s = lc.session;
  CHECK(s.schema_version == manip::session_t::SCHEMA_VERSION);
  CHECK(s.source == "manip_rt/sim");
  CHECK(s.sample_rate_hz == 4000.0);
  CHECK(s.drive_rate_hz == 2000.0);
  CHECK(s.m_adm_kg[0] == 5.0);
  CHECK(s.d_adm_nspm[0] == 15.0);
  CHECK(s.m_handle_kg[1] == 0.25);
  CHECK(s.workspace_origin_in_shoulder_m[1] == 0.425);
  CHECK(s.segment_mass_kg[0] == 1.93);
  CHECK(s.segment_inertia_kgm2[1] == 0.0188);
  CHECK(s.pert_duration_s == 0.15);
  CHECK(s.trigger_x2_shoulder_m == 0.40);
  CHECK(s.participant_id == cfg.session.participant_id);
  CHECK(s.config_yaml == cfg.effective_yaml);
  CHECK(s.config_yaml.find("protocol.movements=" + std::to_string(cfg.protocol.movements)) != std::string::npos);
  CHECK(lc.gaps == 0);
  REQUIRE(static_cast<std::int64_t>(lc.states.size()) == rep.cycles);
  // utime: nominal, 250 us per cycle from the session start
  CHECK(lc.states[10].utime - lc.states[0].utime == 2500);
  CHECK(lc.states[0].utime == s.utime_start);

  // events: START/END pairs, ONSET only on perturbed trials, at the first crossing of the logged x2
  const manip::WorkspaceToShoulder fr = cfg.session.frame;
  const manip::PerturbationProfile prof{0.15, 15.0};
  std::map<int, const manip::trial_event_t*> start_of;
  int onsets = 0;
  for (const auto& e : lc.events) {
    if (e.kind == manip::trial_event_t::START) start_of[e.trial] = &e;
    if (e.kind != manip::trial_event_t::ONSET) continue;
    ++onsets;
    REQUIRE(start_of.count(e.trial));
    CHECK(start_of[e.trial]->perturbed);
    // first cycle after START at which the logged measured x2 (shoulder) reaches the trigger
    std::int64_t expect = -1;
    for (std::int64_t c = start_of[e.trial]->cycle + 1; c < static_cast<std::int64_t>(lc.states.size()); ++c) {
      const auto& a = lc.states[static_cast<std::size_t>(c - 1)];
      const auto& b = lc.states[static_cast<std::size_t>(c)];
      const double x2a = fr.point_to_shoulder(Vec2(a.x_workspace_m[0], a.x_workspace_m[1])).y();
      const double x2b = fr.point_to_shoulder(Vec2(b.x_workspace_m[0], b.x_workspace_m[1])).y();
      if (x2a < 0.40 && x2b >= 0.40) {
        expect = c;
        break;
      }
    }
    CHECK(e.cycle == expect);
    for (int j = 0; j < 700; ++j) {
      const auto& st = lc.states[static_cast<std::size_t>(e.cycle + j)];
      const Vec2 f = fr.vector_to_workspace(prof.force_n(j / 4000.0, e.pert_angle_rad));
      REQUIRE(st.u_pert_workspace_n[0] == Approx(f[0]).margin(1e-12));
      REQUIRE(st.u_pert_workspace_n[1] == Approx(f[1]).margin(1e-12));
    }
  }
  CHECK(onsets == cfg.perturbed_count());
  // every state: trial index inside [START, END], -1 outside; perturbation only inside its trial
  std::size_t ei = 0;
  int current = -1;
  std::int64_t end_cycle = -1;
  for (const auto& st : lc.states) {
    while (ei < lc.events.size() && lc.events[ei].cycle <= st.cycle) {
      const auto& e = lc.events[ei++];
      if (e.kind == manip::trial_event_t::START) current = e.trial;
      if (e.kind == manip::trial_event_t::END || e.kind == manip::trial_event_t::ABORT) end_cycle = e.cycle;
    }
    if (end_cycle >= 0 && st.cycle > end_cycle) {
      current = -1;
      end_cycle = -1;
    }
    REQUIRE(st.trial == current);
  }
  // the rendering: the handle tracked the admittance reference within 0.1 mm throughout
  double track = 0;
  for (const auto& st : lc.states)
    track = std::max(track, std::hypot(st.x_ref_workspace_m[0] - st.x_workspace_m[0],
                                       st.x_ref_workspace_m[1] - st.x_workspace_m[1]));
  WARN("max |x_ref - x| over the session: " << track * 1e3 << " mm");
  CHECK(track < 1e-4);
  std::filesystem::remove(path);
}

TEST_CASE("full 100-movement session: gapless log, 24 perturbations", "[session][full]") {
  if (kSanitized) {
    WARN("skipped under sanitizers: the shortened-session test covers the same path");
    return;
  }
  const RtConfig cfg = load_rt_config(cfg_path());
  const std::string path = tmp("full");
  std::ostringstream out;
  const auto t0 = std::chrono::steady_clock::now();
  const auto rep = run(cfg, path, out);
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  INFO(out.str() << rep.summary());
  REQUIRE(rep.exit_code == ec::kOk);
  const LogContents lc = read_log(path, false);
  std::filesystem::remove(path);
  WARN(cfg.protocol.movements << "-movement session: " << rep.cycles << " cycles (" << rep.cycles / 4000.0
                              << " s simulated) in " << wall << " s wall; loop compute p99 " << rep.timing.compute_p99_us
                              << " us");
  CHECK(lc.session_first);
  CHECK(lc.gaps == 0);
  CHECK(rep.log.states == rep.cycles);
  CHECK(rep.log_drops == 0);
  int starts = 0, ends = 0, onsets = 0, perturbed_ends = 0;
  for (const auto& e : lc.events) {
    starts += e.kind == manip::trial_event_t::START;
    ends += e.kind == manip::trial_event_t::END;
    onsets += e.kind == manip::trial_event_t::ONSET;
    perturbed_ends += e.kind == manip::trial_event_t::END && e.perturbed;
  }
  CHECK(ends == cfg.protocol.movements);
  CHECK(starts == ends + rep.trials.aborted);
  CHECK(onsets == cfg.perturbed_count());
  CHECK(perturbed_ends == cfg.perturbed_count());
}

TEST_CASE("a log that cannot be written at start is refused (exit 6)", "[session][logger]") {
  if (!std::filesystem::exists("/dev/full")) {
    WARN("no /dev/full: skipped");
    return;
  }
  const RtConfig cfg = shortened(4);
  std::ostringstream out;
  const auto rep = run(cfg, "/dev/full", out);
  CHECK(rep.exit_code == ec::kOutput);
  CHECK(rep.message.find("/dev/full") != std::string::npos);  // names the path (exists / cannot truncate a device)
  CHECK(rep.cycles == 0);
  // a directory that does not exist: refused, nothing run
  const auto rep2 = run(cfg, "/nonexistent-manip-dir/s.lcm", out);
  CHECK(rep2.exit_code == ec::kOutput);
  CHECK(rep2.message.find("/nonexistent-manip-dir/s.lcm") != std::string::npos);
  CHECK(rep2.cycles == 0);
}

TEST_CASE("the disk filling up during a session ends it safely and loudly (exit 6)", "[session][logger]") {
  // A file-size limit makes writes fail part-way (EFBIG), like a full disk.
  const RtConfig cfg = shortened(4);
  const auto backend = make_backend("sim", cfg);
  auto* sim = dynamic_cast<hw::SimBackend*>(backend.get());
  REQUIRE(sim);
  const std::string path = tmp("fsize");
  const auto opt = offline_run_options(path);
  std::ostringstream out;
  rlimit old{};
  REQUIRE(getrlimit(RLIMIT_FSIZE, &old) == 0);
  auto* old_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit lim = old;
  lim.rlim_cur = (kSanitized ? 2 : 4) << 20;  // 4 MiB: ~5 s of loop time
  REQUIRE(setrlimit(RLIMIT_FSIZE, &lim) == 0);
  const auto rep = run_session(cfg, *backend, opt, out);
  setrlimit(RLIMIT_FSIZE, &old);
  std::signal(SIGXFSZ, old_handler);
  INFO(rep.summary());
  CHECK(rep.exit_code == ec::kOutput);
  CHECK(rep.stop_reason == StopReason::kLogger);
  CHECK(rep.message.find("File too large") != std::string::npos);
  CHECK((rep.fault_flags & fault::kLogger) != 0u);
  CHECK(rep.cycles > 4000);                      // it ran for a while first
  CHECK(rep.trials.completed < 4);               // and ended early
  CHECK_FALSE(sim->enabled());                   // drives disabled at the end
  CHECK(sim->applied_force_n().norm() == 0.0);
  // what was written is a readable log up to the failure
  const LogContents lc = read_log(path, false);
  CHECK(lc.session_first);
  CHECK(lc.gaps == 0);
  std::filesystem::remove(path);
}

TEST_CASE("backends and options refused with their exit codes", "[session]") {
  const RtConfig cfg = load_rt_config(cfg_path());
  {
    // config/can.yaml (SocketCAN can0/can1) relative to the working directory
    const auto cwd = std::filesystem::current_path();
    std::filesystem::current_path(MANIP_SOURCE_DIR);
    auto can = make_backend("can", cfg);
    std::filesystem::current_path(cwd);
    try {
      can->configure();
      FAIL("backend 'can' started without CAN interfaces");
    } catch (const manip::Error& e) {
      CHECK(e.exit_code() == ec::kBackend);
      CHECK(std::string(e.what()).find("CAN bus 'bus_x' (can0)") != std::string::npos);
    }
  }
  try {
    (void)make_backend("serial", cfg);
    FAIL("backend 'serial' was not refused");
  } catch (const manip::Error& e) {
    CHECK(e.exit_code() == ec::kUsage);
  }

  // an existing log is never overwritten without --force
  const std::string path = tmp("exists");
  { std::FILE* f = std::fopen(path.c_str(), "w"); REQUIRE(f); std::fclose(f); }
  RunOptions opt;
  opt.log_path = path;
  opt.lcm_url = "none";
  std::ostringstream out;
  CHECK(run_session(cfg, *make_backend("sim", cfg), opt, out).exit_code == ec::kOutput);
  std::filesystem::remove(path);

  // a bad LCM URL
  opt.log_path = "";
  opt.lcm_url = "nosuchprovider://x";
  CHECK(run_session(cfg, *make_backend("sim", cfg), opt, out).exit_code == ec::kBus);

  // --require-rt on a kernel without PREEMPT_RT
  if (!detect_rt().preempt_rt) {
    opt.lcm_url = "none";
    opt.realtime = true;
    opt.require_rt = true;
    const auto rep = run_session(cfg, *make_backend("sim", cfg), opt, out);
    CHECK(rep.exit_code == ec::kRealtime);
    CHECK(rep.message.find("PREEMPT_RT") != std::string::npos);
  }
}

TEST_CASE("paced real-time run with the live bus (memq): timing statistics and health", "[session][realtime]") {
  RtConfig cfg = shortened(4);
  // Timing is measured here, not the overrun policy: on a loaded, shared
  // machine a latched overrun fault would (correctly) make the run exit 7.
  cfg.cycle.overrun_fault_consecutive = 100000;
  cfg.cycle.overrun_fault_per_second = 100000;
  RunOptions opt;
  opt.realtime = true;
  opt.duration_s = 0.5;
  opt.lcm_url = "memq://";
  std::ostringstream out;
  const std::string path = tmp("paced");
  const auto rep = run(cfg, path, out, opt);
  INFO(out.str() << rep.summary());
  CHECK(rep.exit_code == ec::kOk);
  CHECK(rep.stop_reason == StopReason::kDuration);
  CHECK(rep.cycles == 2000 + cfg.safety.shutdown_cycles);
  CHECK(rep.wall_s > 0.45);
  CHECK(rep.timing.cycles == rep.cycles);
  CHECK(rep.timing.latency_p50_us > 0.0);
  CHECK(rep.log.missing_cycles == 0);
  const LogContents lc = read_log(path, false);
  CHECK(lc.gaps == 0);
  CHECK(lc.other >= 1);  // health messages from the bus thread are logged too
  std::filesystem::remove(path);
}
