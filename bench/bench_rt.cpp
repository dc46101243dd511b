// bench_rt: the full manip_rt stack (sim backend, controller, logger thread
// writing the LCM log, optional live bus) paced at the sample rate with
// SCHED_FIFO for a fixed time; prints wake-up latency and compute-time
// percentiles, overruns and logger drops as one JSON object.
// Run by bench/run_rt_bench.sh next to cyclictest (docs/controller.md).
#include <CLI/CLI.hpp>

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>

#include "manip/runtime/config.hpp"
#include "manip/runtime/session.hpp"
#include "manip/hardware/sim_backend.hpp"

int main(int argc, char** argv) {
  CLI::App app{"bench_rt: paced manip_rt loop on the sim backend; JSON timing summary on stdout"};
  std::string config = "config/rt.yaml", log = "", lcm_url = "none", histogram;
  double seconds = 60.0;
  int priority = 80, cpu = -1;
  app.add_option("--config", config)->capture_default_str();
  app.add_option("--seconds", seconds, "paced run duration")->capture_default_str();
  app.add_option("--priority", priority, "SCHED_FIFO priority")->capture_default_str();
  app.add_option("--cpu", cpu, "pin the loop to this CPU (-1: no affinity)")->capture_default_str();
  app.add_option("--log", log, "log file (default: a temporary file, deleted afterwards)");
  app.add_option("--lcm-url", lcm_url, "live bus URL ('none': no bus)")->capture_default_str();
  app.add_option("--histogram", histogram, "write the wake-up latency histogram (cyclictest -h format: 'us count')");
  CLI11_PARSE(app, argc, argv);

  const std::string path =
      log.empty() ? (std::filesystem::temp_directory_path() / ("bench_rt_" + std::to_string(::getpid()) + ".lcm")).string()
                  : log;
  try {
    const manip::runtime::RtConfig cfg = manip::runtime::load_rt_config(
        config, {{"loop.priority", std::to_string(priority)}, {"loop.cpu", std::to_string(cpu)}});
    manip::hardware::SimBackend sim(cfg, cfg.sim, manip::hardware::make_sim_human(cfg, cfg.sim));
    manip::runtime::RunOptions opt;
    opt.log_path = path;
    opt.overwrite_log = true;
    opt.realtime = true;
    opt.duration_s = seconds;
    opt.lcm_url = lcm_url;
    opt.quiet = true;
    const auto rep = manip::runtime::run_session(cfg, sim, opt, std::cerr);
    if (log.empty()) std::filesystem::remove(path);
    if (!histogram.empty()) {
      std::FILE* f = std::fopen(histogram.c_str(), "w");
      if (!f) {
        std::cerr << "bench_rt: cannot write " << histogram << "\n";
        return 1;
      }
      const auto& h = rep.latency_histogram;
      for (std::size_t i = 0; i + 1 < h.size(); ++i)
        if (h[i]) std::fprintf(f, "%06zu %06lld\n", i, static_cast<long long>(h[i]));
      std::fprintf(f, "# Histogram Overflows: %lld\n", static_cast<long long>(h.empty() ? 0 : h.back()));
      std::fclose(f);
    }
    const auto& t = rep.timing;
    std::printf(
        "{\"cycles\": %lld, \"wall_s\": %.3f, \"latency_p50_us\": %.0f, \"latency_p99_us\": %.0f, "
        "\"latency_p999_us\": %.0f, \"latency_max_us\": %.1f, \"compute_p50_us\": %.1f, \"compute_p99_us\": %.1f, "
        "\"compute_p999_us\": %.1f, \"compute_max_us\": %.1f, \"overruns\": %lld, \"skipped_periods\": %lld, "
        "\"logger_drops\": %lld, \"log_missing_cycles\": %lld, \"fault_flags\": \"%s\", \"exit_code\": %d}\n",
        static_cast<long long>(rep.cycles), rep.wall_s, t.latency_p50_us, t.latency_p99_us, t.latency_p999_us,
        t.latency_max_us, t.compute_p50_us, t.compute_p99_us, t.compute_p999_us, t.compute_max_us,
        static_cast<long long>(t.overruns), static_cast<long long>(t.skipped_periods),
        static_cast<long long>(rep.log_drops), static_cast<long long>(rep.log.missing_cycles),
        manip::control::fault_names(rep.fault_flags).c_str(), rep.exit_code);
    if (rep.exit_code != 0) std::cerr << "bench_rt: " << rep.message << "\n";
    return rep.exit_code;
  } catch (const std::exception& e) {
    std::cerr << "bench_rt: " << e.what() << "\n";
    return 1;
  }
}
