// Estimator throughput on one session log (docs/benchmarks.md, "## Estimator").
//   floor      read_log + decode only (handler touches each decoded state)
//   e2e-paper  estimate_log with methods = {"paper"}
//   e2e-default     estimate_log with the default methods ({"pem"})
//   proc-paper SessionEstimator (add_trial + finish) on trials already in memory, {"paper"}
//   proc-default    the same with the default methods
// The measurements are interleaved per repetition (the machine is noisy); the
// median, min and max of each are printed, one line each:
//   RESULT <name> median_s=<> min_s=<> max_s=<> reps=<>
// For proc-*, copying the in-memory trials for each repetition is not timed.
// Each also gets a <name>-cpu line: process CPU time (all threads) of the same runs.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include <sys/resource.h>
#include <time.h>

#include <CLI/CLI.hpp>

#include "manip/estimation/session_estimator.hpp"
#include "manip/estimation/trial_data.hpp"
#include "manip/logging/session_stream.hpp"

namespace {

using Clock = std::chrono::steady_clock;
namespace est = manip::estimation;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// CPU time of the whole process (all threads): less sensitive than wall time to
// other users of a shared machine (not to their cache and memory traffic).
double process_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

class TouchHandler final : public manip::logging::SessionHandler {
 public:
  void on_state(const manip::state_t& s) override {
    sum += s.x_workspace_m[1];
    ++n;
  }
  void on_truth_state(const manip::state_t& s) override {
    sum += s.x_workspace_m[1];
    ++n_truth;
  }
  void on_trial_event(const manip::trial_event_t& e) override { sum += static_cast<double>(e.kind); }
  double sum{0};
  long n{0}, n_truth{0};
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const auto n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Keeps the optimiser from dropping a result.
volatile double g_sink = 0;

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Estimator benchmark: decode floor, end to end, processing alone"};
  std::string log;
  int reps = 5;
  std::vector<std::string> only;
  app.add_option("log", log, "LCM session log")->required()->check(CLI::ExistingFile);
  app.add_option("--reps", reps, "repetitions (>= 1; median reported)");
  app.add_option("--only", only, "subset of: floor e2e-paper e2e-default proc-paper proc-default");
  CLI11_PARSE(app, argc, argv);
  auto want = [&](const std::string& n) { return only.empty() || std::find(only.begin(), only.end(), n) != only.end(); };

  est::EstimatorSettings paper;
  paper.methods = {"paper"};
  est::EstimatorSettings dflt;  // default methods

  // Trials in memory for the processing-only runs (loaded once, not timed).
  est::SessionInfo info;
  std::vector<est::TrialData> trials;
  std::vector<est::TrialIssue> issues;
  std::vector<std::string> warnings;
  std::size_t samples = 0;
  if (want("proc-paper") || want("proc-default")) {
    const auto t0 = Clock::now();
    est::TrialAssembler asmb([&](const est::SessionInfo& i, est::TrialData&& t) {
      info = i;
      samples += t.size();
      trials.push_back(std::move(t));
    });
    manip::logging::read_log(log, asmb);
    asmb.finish();
    issues = asmb.issues();
    warnings = asmb.warnings();
    std::fprintf(stderr, "loaded %zu trials (%zu samples) in %.3f s\n", trials.size(), samples, seconds_since(t0));
  }

  std::map<std::string, std::vector<double>> t;
  for (int r = 0; r < reps; ++r) {
    if (want("floor")) {
      TouchHandler h;
      const double c0 = process_cpu_s();
      const auto t0 = Clock::now();
      manip::logging::read_log(log, h);
      t["floor"].push_back(seconds_since(t0));
      t["floor-cpu"].push_back(process_cpu_s() - c0);
      g_sink = g_sink + h.sum;
      if (r == 0) std::fprintf(stderr, "floor: %ld states, %ld twin states\n", h.n, h.n_truth);
    }
    for (const auto& [name, s] : {std::pair{std::string("e2e-paper"), paper}, std::pair{std::string("e2e-default"), dflt}}) {
      if (!want(name)) continue;
      const double c0 = process_cpu_s();
      const auto t0 = Clock::now();
      const auto rep = est::estimate_log(log, s);
      t[name].push_back(seconds_since(t0));
      t[name + "-cpu"].push_back(process_cpu_s() - c0);
      g_sink = g_sink + rep.summaries.size();
      if (r == 0) std::fprintf(stderr, "%s: %d trials, %d perturbed, %d used\n", name.c_str(), rep.n_trials, rep.n_perturbed, rep.n_used);
    }
    for (const auto& [name, s] : {std::pair{std::string("proc-paper"), paper}, std::pair{std::string("proc-default"), dflt}}) {
      if (!want(name)) continue;
      auto copy = trials;  // not timed
      auto iss = issues;
      auto warn = warnings;
      const double c0 = process_cpu_s();
      const auto t0 = Clock::now();
      est::SessionEstimator e(s);
      for (auto& tr : copy) e.add_trial(info, std::move(tr));
      const auto rep = e.finish(std::move(iss), std::move(warn));
      t[name].push_back(seconds_since(t0));
      t[name + "-cpu"].push_back(process_cpu_s() - c0);
      g_sink = g_sink + rep.summaries.size();
    }
  }
  for (const auto& name : {"floor", "e2e-paper", "e2e-default", "proc-paper", "proc-default", "floor-cpu", "e2e-paper-cpu",
                            "e2e-default-cpu", "proc-paper-cpu", "proc-default-cpu"}) {
    const auto it = t.find(name);
    if (it == t.end()) continue;
    const auto& v = it->second;
    std::printf("RESULT %s median_s=%.4f min_s=%.4f max_s=%.4f reps=%zu\n", name, median(v),
                *std::min_element(v.begin(), v.end()), *std::max_element(v.begin(), v.end()), v.size());
  }
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  std::printf("RESULT bench_maxrss_mb %.1f\n", static_cast<double>(ru.ru_maxrss) / 1024.0);
  return 0;
}
