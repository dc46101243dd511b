// Wall time of a full manipulandum diagnosis (docs/benchmarks.md, "## Diagnosis"):
// diagnose_model's whole pipeline on one session log, as the app runs it:
// read the log (truth channels dropped), isolate the variational signals of
// every perturbed trial (eq. 21), fit the estimator's default method (pem),
// the engine (baseline, signatures, 10-fold mechanism search, 200 bootstrap
// replicates) and the default method refitted with the extension.
//   bench_diagnosis [--log LOG] [--hidden delay:0.002] [--movements 100] [--reps 5]
// Without --log a hidden session (realistic noise, hidden seed 1) is written
// to $TMPDIR and removed afterwards. Prints per repetition and
//   RESULT diagnosis median_s=<> min_s=<> max_s=<> cpu_median_s=<> reps=<>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <time.h>

#include <CLI/CLI.hpp>

#include "manip/common/cli.hpp"
#include "manip/diagnosis/likelihood_stage.hpp"
#include "manip/diagnosis/manipulandum.hpp"
#include "manip/logging/session_stream.hpp"
#include "manip/sim/hidden_effects.hpp"
#include "manip/sim/presets.hpp"

namespace {
using Clock = std::chrono::steady_clock;
double cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}
}  // namespace

// Bad input (a missing or unreadable --log) ends with one line and its exit
// code (docs/exit-codes.md), as in the apps.
int run_bench(int argc, char** argv) {
  using namespace manip;
  CLI::App app{"bench_diagnosis: wall time of a full manipulandum diagnosis"};
  std::string log, hidden = "delay:0.002";
  int movements = 100, reps = 5;
  app.add_option("--log", log, "session log (default: write a hidden session)");
  app.add_option("--hidden", hidden, "hidden mechanism of the generated session (\"none\" for a clean one)");
  app.add_option("--movements", movements, "movements of the generated session");
  app.add_option("--reps", reps, "repetitions")->check(CLI::Range(1, 100));
  CLI11_PARSE(app, argc, argv);
  bool generated = false;
  if (log.empty()) {
    log = (std::filesystem::temp_directory_path() / "bench_diagnosis.lcm").string();
    sim::SessionDesign base;
    base.n_movements = movements;
    base.session.source = "manip_sim/linear";
    auto person = sim::table1_person();
    sim::apply_noise(sim::NoiseLevel::realistic, base, person);
    std::vector<sim::HiddenEffect> eff;
    if (hidden != "none") eff.push_back(sim::parse_hidden_effect(hidden));
    auto hs = sim::make_hidden_session(base, person, eff, 1);
    logging::LogWritingHandler w(log);
    (void)sim::run_session(hs.design, *hs.person, w);
    w.close();
    generated = true;
    std::printf("generated %s (%d movements, hidden %s, %.0f MB)\n", log.c_str(), movements, hidden.c_str(),
                static_cast<double>(std::filesystem::file_size(log)) / 1e6);
  }
  std::vector<double> wall, cpu;
  std::string named;
  for (int r = 0; r < reps; ++r) {
    const auto t0 = Clock::now();
    const double c0 = cpu_s();
    std::vector<diagnosis::CollectedSession> ses;
    ses.push_back(diagnosis::collect_log(log));
    diagnosis::PlanarOptions po;
    diagnosis::EngineOptions eo;
    const auto run = diagnosis::run_planar(ses, po, eo);
    const auto rep = diagnosis::planar_report(run.prep, run.dg, run.lib);
    const auto& dg = run.dg;
    wall.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
    cpu.push_back(cpu_s() - c0);
    named = run.concl.named.empty() ? "none" : run.concl.named.front();
    std::printf("rep %d: %.3f s wall, %.3f s CPU (engine %.3f s), named: %s\n", r + 1, wall.back(), cpu.back(), dg.seconds, named.c_str());
  }
  std::printf("RESULT diagnosis median_s=%.3f min_s=%.3f max_s=%.3f cpu_median_s=%.3f reps=%d\n", median(wall),
              *std::min_element(wall.begin(), wall.end()), *std::max_element(wall.begin(), wall.end()), median(cpu), reps);
  if (generated) std::filesystem::remove(log);
  return 0;
}

int main(int argc, char** argv) { return manip::cli::run_main("bench_diagnosis", run_bench, argc, argv); }
