// manip_rt: the 4 kHz admittance controller of the manipulandum (docs/controller.md).
#include <csignal>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <iostream>

#include <nlohmann/json.hpp>

#include "manip/common/cli.hpp"
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

// The rows of the one table (common/exit_codes.hpp) manip_rt returns, in the
// order --help prints them; what each means for manip_rt is in kExitNotes.
const std::vector<int> kExitCodes = {manip::exit_code::kOk,       manip::exit_code::kUsage,   manip::exit_code::kConfig,
                                     manip::exit_code::kOutput,   manip::exit_code::kFault,   manip::exit_code::kBackend,
                                     manip::exit_code::kRealtime, manip::exit_code::kBus,     manip::exit_code::kInternal,
                                     manip::exit_code::kInterrupted};
const char* kExitNotes =
    "What the codes mean for manip_rt:\n"
    "    0: session complete, stopped by STOP_SESSION, or --duration reached\n"
    "    3: rt.yaml (or --can-config, the arm model) invalid, unreadable or not found\n"
    "       (the message names file, line, key, reason, or every directory searched)\n"
    "    6: log exists (use --force), in use by another running manip_rt, cannot be created,\n"
    "       or writing failed (e.g. disk full)\n"
    "    7: session ended by a safety fault (unattended runs, --exit-on-fault), or reached\n"
    "       --duration or its end with a fault still latched\n"
    "    8: backend unavailable or failed to start (CAN interface, drive start-up, bus budget)\n"
    "    9: --require-rt and no PREEMPT_RT kernel, no real-time privileges, or the loop thread\n"
    "       could not get SCHED_FIFO/mlock (checked before the first cycle)\n"
    "   10: LCM bus cannot be created with the URL (--lcm-url none runs without it)\n"
    "  130: SIGINT, SIGTERM or SIGHUP: stopped safely, log closed\n";

// rt.yaml's sim.human.arm_config (neuromech person) as found from any
// directory: as written if it exists (relative to the working directory, as
// before), else beside rt.yaml, else its file name on the --config search path
// (so the packaged rt.yaml's "config/arm_model.yaml" is found when installed).
std::string resolve_arm_config(const std::string& written, const std::string& rt_yaml) {
  namespace fs = std::filesystem;
  std::error_code e;
  const fs::path p(written);
  if (p.is_absolute() || fs::exists(p, e)) return written;
  const fs::path beside = fs::path(rt_yaml).parent_path() / p.filename();
  if (fs::is_regular_file(beside, e)) return beside.string();
  try {
    return manip::cli::find_config(p.filename().string(), p.filename().string());
  } catch (const manip::ConfigError& err) {
    throw manip::ConfigError(rt_yaml + ": sim.human.arm_config: " + err.what());
  }
}
}  // namespace

int run(int argc, char** argv) {
  namespace rt = manip::runtime;
  namespace ec = manip::exit_code;
  namespace cli = manip::cli;
  CLI::App app{std::string("manip_rt ") + manip::kVersion +
                   ": 4 kHz admittance controller of the 2-axis manipulandum (paper §5.1-5.2)",
               "manip_rt"};
  app.footer(kExitNotes);
  cli::Common c;
  std::string backend = "sim", lcm_url, can_config;
  bool realtime = false, afap = false, require_rt = false, exit_on_fault = false;
  double duration = 0.0;
  long long seed = -1;
  cli::add_version(app, "manip_rt");
  cli::add_quiet(app, c.quiet);
  app.add_option("--backend", backend, "sim | can (CANopen CiA 402 drives, docs/hardware.md)")
      ->check(cli::one_of({"sim", "can"}))
      ->capture_default_str();
  bool can_virtual = false;
  cli::add_config(app, c.config, "rt.yaml", "controller configuration");
  app.add_option("--can-config", can_config,
                 "--backend can: CANopen bus configuration (default can.yaml, searched like --config)");
  app.add_flag("--can-virtual", can_virtual, "--backend can: simulated drives on an in-process virtual bus");
  cli::add_out(app, c.out, "LCM log to write (default manip_rt-<session_id>-<UTC time>.lcm)");
  cli::add_deprecated_alias(app, "--log", "--out", c.out);
  cli::add_force(app, c.force);
  auto* rt_flag = app.add_flag("--realtime", realtime, "pace the loop in real time at the sample rate (SCHED_FIFO)");
  app.add_flag("--afap,--as-fast-as-possible", afap, "run the simulation as fast as possible (default for sim)")
      ->excludes(rt_flag);
  app.add_flag("--require-rt", require_rt, "refuse to run without a PREEMPT_RT kernel and real-time privileges");
  app.add_option("--lcm-url", lcm_url, "LCM URL for the live bus (default: bus.lcm_url; 'none' = no bus)");
  app.add_option("--duration", duration, "stop after this many seconds of loop time (0 = whole session)")
      ->check(cli::finite_range(0.0, 1e7));
  constexpr int kMaxMovements = 100000;
  app.add_option("--movements", c.movements,
                 "shorten or lengthen the session to N movements, keeping the perturbed fraction (default: "
                 "protocol.movements of rt.yaml)")
      ->check(CLI::Range(1, kMaxMovements));
  cli::add_deprecated_alias(app, "--trials", "--movements", c.movements)->check(CLI::Range(1, kMaxMovements));
  app.add_option("--seed", seed, "override protocol.seed (recorded in the session message)")
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--exit-on-fault", exit_on_fault, "end the run on a safety fault (default when not paced)");
  cli::set_exit_codes(app, kExitCodes);
  if (const auto rc = cli::parse(app, argc, argv)) return *rc;
  const bool quiet = c.quiet;

  // rt.yaml from any directory (docs/cli.md): as given, $MANIP_CONFIG_DIR,
  // ~/.config/manip, <prefix>/share/manip/config, ...
  const std::string config = cli::find_config(c.config, "rt.yaml");
  rt::ConfigOverrides ov;
  if (!lcm_url.empty()) ov.emplace_back("bus.lcm_url", "\"" + lcm_url + "\"");
  if (seed >= 0) ov.emplace_back("protocol.seed", std::to_string(seed));
  rt::RtConfig cfg = rt::load_rt_config(config, ov);
  bool reload = false;
  if (c.movements > 0) {
    for (auto& o : rt::trials_overrides(cfg, c.movements)) ov.push_back(o);
    reload = true;
  }
  if (backend == "sim" && cfg.sim.human.model == "neuromech" && !cfg.sim.human.arm_config.empty()) {
    const std::string arm = resolve_arm_config(cfg.sim.human.arm_config, config);
    if (arm != cfg.sim.human.arm_config) {
      nlohmann::json quoted = arm;  // a YAML double-quoted scalar is a JSON string
      ov.emplace_back("sim.human.arm_config", quoted.dump());
      reload = true;
    }
  }
  if (reload) cfg = rt::load_rt_config(config, ov);

  if (backend == "can" && !afap) realtime = true;
  std::unique_ptr<manip::hardware::Backend> hw_backend;
  if (backend == "can") {
    auto can = manip::hardware::load_can_config(cli::find_config(can_config, "can.yaml"));
    if (can_virtual) can.backend.virtual_bus = true;
    hw_backend = std::make_unique<manip::hardware::CanBackend>(cfg, cfg.sim, can);
  } else {
    hw_backend = rt::make_backend(backend, cfg);
  }
  std::string log = c.out;
  if (log.empty()) {
    char ts[32];
    const std::time_t now = std::time(nullptr);
    std::strftime(ts, sizeof ts, "%Y%m%dT%H%M%SZ", std::gmtime(&now));
    log = "manip_rt-" + cfg.session.session_id + "-" + ts + ".lcm";
  }

  rt::RunOptions opt;
  opt.log_path = log;
  opt.overwrite_log = c.force;
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
    std::cerr << "manip_rt " << manip::kVersion << ": backend " << backend << ", config " << config << ", "
              << (opt.realtime ? "paced in real time" : "as fast as possible") << ", " << cfg.protocol.movements
              << " movements (" << cfg.perturbed_count() << " perturbed), log " << log << "\n";
  const rt::RunReport rep = rt::run_session(cfg, *hw_backend, opt, std::cerr);
  if (rep.cycles > 0 && (!quiet || rep.exit_code != 0)) std::cerr << rep.summary();
  // -q: silent on success (docs/cli.md); how a session ended otherwise is always said.
  if (!quiet || rep.exit_code != ec::kOk) std::cerr << "manip_rt: " << rep.message << " (exit " << rep.exit_code << ")\n";
  return rep.exit_code;
}

int main(int argc, char** argv) {
  install_signal_handlers();  // before the first write to stderr (SIGPIPE)
  try {
    return run(argc, argv);
  } catch (const manip::ConfigError& e) {
    std::cerr << "manip_rt: configuration error: " << e.what() << "\n";
    return e.exit_code();
  } catch (const manip::Error& e) {
    std::cerr << "manip_rt: " << e.what() << "\n";
    return e.exit_code();
  } catch (const std::exception& e) {
    std::cerr << "manip_rt: internal error: " << e.what() << "\n";
    return manip::exit_code::kInternal;
  }
}
