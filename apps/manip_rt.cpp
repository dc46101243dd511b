// manip_rt: the 4 kHz admittance controller of the manipulandum (docs/controller.md).
#include <CLI/CLI.hpp>

#include <csignal>
#include <cmath>
#include <ctime>
#include <iostream>

#include "manip/common/errors.hpp"
#include "manip/common/exit_codes.hpp"
#include "manip/hardware/can_backend.hpp"
#include "manip/runtime/backends.hpp"
#include "manip/runtime/config.hpp"
#include "manip/runtime/session.hpp"
#include "manip/version.hpp"

namespace {
std::atomic<bool> g_interrupt{false};
std::atomic<int> g_signal{0};
extern "C" void on_signal(int sig) {
  int expected = 0;
  g_signal.compare_exchange_strong(expected, sig);  // the first signal names the reason
  g_interrupt.store(true);
}

// SIGINT, SIGTERM and SIGHUP (closed terminal, dropped ssh session) all mean
// "stop safely": safe law, STOPPED cycles, log closed, summary, exit 130.
// SIGPIPE is ignored: a closed stdout/stderr (`manip_rt ... 2>&1 | head -1`)
// makes writes fail with EPIPE instead of killing the controller; progress
// and summary output then stop, the session and its log do not.
void install_signal_handlers() {
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaction(sig, &sa, nullptr);
  struct sigaction ign {};
  ign.sa_handler = SIG_IGN;
  sigemptyset(&ign.sa_mask);
  sigaction(SIGPIPE, &ign, nullptr);
}

// The rows of common/exit_codes.hpp that manip_rt uses.
const char* kExitCodes =
    "Exit codes (the table shared by every manip program):\n"
    "  0    session complete, stopped by STOP_SESSION, or --duration reached\n"
    "  2    bad command line\n"
    "  3    configuration invalid or unreadable (message names file, line, key, reason)\n"
    "  6    log file exists (use --force), in use by another running manip_rt, cannot be created,\n"
    "       or writing failed (e.g. disk full)\n"
    "  7    session ended by a safety fault (unattended runs, --exit-on-fault), or reached\n"
    "       --duration or its end with a fault still latched\n"
    "  8    backend unavailable or failed to start (CAN interface, drive start-up, bus budget)\n"
    "  9    --require-rt: no PREEMPT_RT kernel, no real-time privileges, or the loop thread\n"
    "       could not get SCHED_FIFO/mlock (checked before the first cycle)\n"
    "  10   LCM bus cannot be created with the URL (--lcm-url none runs without it)\n"
    "  70   unexpected internal error (a bug: please report it)\n"
    "  130  interrupted (SIGINT, SIGTERM or SIGHUP): stopped safely, log closed\n";
}  // namespace

int main(int argc, char** argv) {
  install_signal_handlers();  // before the first write to stderr (SIGPIPE)
  namespace rt = manip::runtime;
  namespace ec = manip::exit_code;
  CLI::App app{std::string("manip_rt ") + manip::kVersion +
               ": 4 kHz admittance controller of the 2-axis manipulandum (paper §5.1-5.2)"};
  app.footer(kExitCodes);
  std::string backend = "sim", config = "config/rt.yaml", log, lcm_url;
  bool realtime = false, afap = false, require_rt = false, force = false, exit_on_fault = false, quiet = false;
  double duration = 0.0;
  int trials = 0;
  long long seed = -1;
  app.add_option("--backend", backend, "sim | can (CANopen CiA 402 drives, docs/hardware.md)")->capture_default_str();
  std::string can_config = "config/can.yaml";
  bool can_virtual = false;
  app.add_option("--can-config", can_config, "--backend can: CANopen bus configuration")->capture_default_str();
  app.add_flag("--can-virtual", can_virtual, "--backend can: simulated drives on an in-process virtual bus");
  app.add_option("--config", config, "configuration YAML")->capture_default_str();
  app.add_option("--log", log, "LCM log file to write (default: manip_rt-<session_id>-<UTC time>.lcm)");
  app.add_flag("--force", force, "overwrite an existing log file");
  auto* rt_flag = app.add_flag("--realtime", realtime, "pace the loop in real time at the sample rate (SCHED_FIFO)");
  app.add_flag("--afap,--as-fast-as-possible", afap, "run the simulation as fast as possible (default for sim)")
      ->excludes(rt_flag);
  app.add_flag("--require-rt", require_rt, "refuse to run without a PREEMPT_RT kernel and real-time privileges");
  app.add_option("--lcm-url", lcm_url, "LCM URL for the live bus (default: bus.lcm_url; 'none' = no bus)");
  app.add_option("--duration", duration, "stop after this many seconds of loop time (0 = whole session)")
      ->check(CLI::Validator(
          [](std::string& v) -> std::string {
            // CLI::NonNegativeNumber lets "nan" through (NaN < 0 is false).
            double d = 0.0;
            std::size_t used = 0;
            try {
              d = std::stod(v, &used);
            } catch (const std::exception&) {
              return "not a number: '" + v + "'";
            }
            if (used != v.size() || !std::isfinite(d) || d < 0.0)
              return "must be a finite number of seconds >= 0 (got '" + v + "')";
            return {};
          },
          "SECONDS >= 0"));
  app.add_option("--trials", trials, "shorten the session to N movements (keeps the perturbed fraction)")
      ->check(CLI::PositiveNumber);
  app.add_option("--seed", seed, "override protocol.seed (recorded in the session message)")
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--exit-on-fault", exit_on_fault, "end the run on a safety fault (default when not paced)");
  app.add_flag("--quiet", quiet, "no progress lines");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : ec::kUsage;
  }

  try {
    rt::ConfigOverrides ov;
    if (!lcm_url.empty()) ov.emplace_back("bus.lcm_url", "\"" + lcm_url + "\"");
    if (seed >= 0) ov.emplace_back("protocol.seed", std::to_string(seed));
    rt::RtConfig cfg = rt::load_rt_config(config, ov);
    if (trials > 0) {
      for (auto& o : rt::trials_overrides(cfg, trials)) ov.push_back(o);
      cfg = rt::load_rt_config(config, ov);
    }

    if (backend == "can" && !afap) realtime = true;
    std::unique_ptr<manip::hardware::Backend> hw_backend;
    if (backend == "can") {
      auto can = manip::hardware::load_can_config(can_config);
      if (can_virtual) can.backend.virtual_bus = true;
      hw_backend = std::make_unique<manip::hardware::CanBackend>(cfg, cfg.sim, can);
    } else {
      hw_backend = rt::make_backend(backend, cfg);
    }
    if (log.empty()) {
      char ts[32];
      const std::time_t now = std::time(nullptr);
      std::strftime(ts, sizeof ts, "%Y%m%dT%H%M%SZ", std::gmtime(&now));
      log = "manip_rt-" + cfg.session.session_id + "-" + ts + ".lcm";
    }

    rt::RunOptions opt;
    opt.log_path = log;
    opt.overwrite_log = force;
    opt.realtime = realtime && !afap;
    opt.require_rt = require_rt;
    opt.lcm_url = lcm_url;
    opt.duration_s = duration;
    opt.exit_on_fault = exit_on_fault;
    opt.quiet = quiet;
    opt.interrupt = &g_interrupt;
    opt.interrupt_signal = &g_signal;
    opt.source = "manip_rt/" + backend;
    if (!quiet)
      std::cerr << "manip_rt " << manip::kVersion << ": backend " << backend << ", "
                << (opt.realtime ? "paced in real time" : "as fast as possible") << ", "
                << cfg.protocol.movements << " movements (" << cfg.perturbed_count() << " perturbed), log " << log
                << "\n";
    const rt::RunReport rep = rt::run_session(cfg, *hw_backend, opt, std::cerr);
    if (rep.cycles > 0 && (!quiet || rep.exit_code != 0)) std::cerr << rep.summary();
    std::cerr << "manip_rt: " << rep.message << " (exit " << rep.exit_code << ")\n";
    return rep.exit_code;
  } catch (const manip::ConfigError& e) {
    std::cerr << "manip_rt: configuration error: " << e.what() << "\n";
    return e.exit_code();
  } catch (const manip::Error& e) {
    std::cerr << "manip_rt: " << e.what() << "\n";
    return e.exit_code();
  } catch (const std::exception& e) {
    std::cerr << "manip_rt: internal error: " << e.what() << "\n";
    return ec::kInternal;
  }
}
