// Speed of the neuromechanical arm on the ideal admittance: simulated seconds per
// wall-clock second on one core (target >= 500x real time at 4 kHz).
//
//   bench_neuromech [--config config/arm_model.yaml] [--runs 7] [--trials 10]
//
// The wall-clock ratio is the figure asked for; on a shared machine it also counts
// time the thread waited for a core, so the ratio per CPU second of this thread is
// printed beside it.
//
// Each run simulates `trials` paired reaches (unperturbed twin + 15 N perturbed,
// 4.0 s each, the paper's feedback configuration with noise) and reports the median
// over runs of the simulated/wall ratio, for:
//   A: plant at 4 kHz, model step 1/4 kHz, midpoint plant step: manip_sim's session
//      runner (integration.session_step_s)
//   B: plant at 16 kHz, model step 1/16 kHz, explicit plant step: manip_rt's sim
//      backend as configured (4 kHz loop x 4 substeps, integration.step_s)
//   C: plant at 16 kHz sub-stepping a 1/4 kHz model, explicit: the sim backend if
//      its start-up check allowed a substep that is a fraction of the model step
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <ctime>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <vector>

#include "manip/common/perturbation.hpp"
#include "manip/sim/ideal_admittance.hpp"
#include "manip/sim/neuromech_arm.hpp"
#include "manip/sim/session_runner.hpp"

using namespace manip;
using namespace manip::sim;

namespace {

double thread_cpu_s() {  // CPU time of this thread: immune to other processes on a shared box
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

struct Result {
  double sim_s{0};
  double wall_s{0};
  double cpu_s{0};
  double checksum{0};  // keeps the work observable
};

Result run(const NeuromechParams& p, double plant_hz, bool midpoint, int trials) {
  NeuromechanicalArm arm(p);  // allocation happens here, outside the timed loop
  const PlantParams plant = plant_params(default_sim_session());
  const PerturbationProfile prof;
  const double dt = 1.0 / plant_hz;
  const ReachSpec reach;
  const auto n = static_cast<long>(std::lround(4.0 * plant_hz));
  Result r;
  const double c0 = thread_cpu_s();
  const auto t0 = std::chrono::steady_clock::now();
  for (int t = 0; t < trials; ++t) {
    for (const double amp : {0.0, 15.0}) {
      arm.begin_trial(reach, static_cast<std::uint64_t>(t + 1));
      long onset = -1;
      const double angle = (30.0 + 45.0 * t) * std::numbers::pi / 180.0;
      for (long k = 0; k < n; ++k) {
        if (onset < 0 && arm.hand_position_m().y() >= 0.40) onset = k;
        const Vec2 u = onset >= 0 ? Vec2(amp * prof.force_n(static_cast<double>(k - onset) * dt, angle) / 15.0)
                                  : Vec2::Zero();
        step_ideal_admittance(arm, plant, u, dt, midpoint);
      }
      r.checksum += arm.hand_position_m().sum();
      r.sim_s += static_cast<double>(n) * dt;
    }
  }
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  r.cpu_s = thread_cpu_s() - c0;
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"neuromechanical arm + ideal admittance: simulated seconds per wall-clock second"};
  std::string config =
      (std::filesystem::path(__FILE__).parent_path().parent_path() / "config" / "arm_model.yaml").string();
  int runs = 7, trials = 10;
  app.add_option("--config", config, "arm model YAML");
  app.add_option("--runs", runs, "repetitions (median reported)");
  app.add_option("--trials", trials, "paired trials per run");
  CLI11_PARSE(app, argc, argv);

  const NeuromechParams base = load_neuromech_params(config);
  struct Case {
    const char* name;
    double step_s, plant_hz;
    bool midpoint;
  };
  const Case cases[] = {{"A plant 4 kHz, step 1/4 kHz, midpoint  ", base.session_step_s, 4000.0, true},
                        {"B plant 16 kHz, step 1/16 kHz, explicit", base.step_s, 16000.0, false},
                        {"C plant 16 kHz, step 1/4 kHz, explicit ", 1.0 / 4000.0, 16000.0, false}};
  std::printf("config %s; %d runs x %d paired trials x 2 x 4.0 s; feedback as configured, noise on\n", config.c_str(),
              runs, trials);
  for (const Case& c : cases) {
    NeuromechParams p = base;
    p.step_s = c.step_s;
    std::vector<double> wall, cpu;
    double checksum = 0.0;
    for (int i = 0; i < runs; ++i) {
      const Result r = run(p, c.plant_hz, c.midpoint, trials);
      wall.push_back(r.sim_s / r.wall_s);
      cpu.push_back(r.sim_s / r.cpu_s);
      checksum += r.checksum;
    }
    std::sort(wall.begin(), wall.end());
    std::sort(cpu.begin(), cpu.end());
    std::printf("%s: wall-clock median %6.0fx real time (min %.0fx, max %.0fx); per CPU second median %6.0fx; "
                "%.2f us per plant step  [checksum %.6f]\n",
                c.name, wall[wall.size() / 2], wall.front(), wall.back(), cpu[cpu.size() / 2],
                1e6 / (c.plant_hz * cpu[cpu.size() / 2]), checksum);
  }
  return 0;
}
