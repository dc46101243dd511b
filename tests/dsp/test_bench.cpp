// Timings of the signal chain on one 3 s, 4 kHz trial. Hidden from ctest
// ([.bench]); run: ./build-dsp/tests/test_dsp "[.bench]"
// Times are per-thread CPU time (CLOCK_THREAD_CPUTIME_ID), best of N: the
// development machines are shared, and wall-clock time mostly measured how
// often the scheduler ran someone else. Compare with scipy measured the same
// way (time.thread_time / process_time).
#include <catch2/catch.hpp>

#include <algorithm>
#include <ctime>
#include <cstdio>

#include "dsp_test_util.hpp"
#include "manip/dsp/dsp.hpp"

namespace {
template <class F>
double best_us(F&& f, int reps) {
  double best = 1e300;
  for (int r = 0; r < reps; ++r) {
    timespec t0{}, t1{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t0);
    f();
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t1);
    best = std::min(best, (static_cast<double>(t1.tv_sec - t0.tv_sec) * 1e9 + static_cast<double>(t1.tv_nsec - t0.tv_nsec)) * 1e-3);
  }
  return best;
}
volatile double g_sink = 0.0;
}  // namespace

TEST_CASE("dsp timings on a 12000-sample trial", "[.bench]") {
  using namespace manip::dsp;
  const auto pos = test::quantised_signal("dsp/trial_position.txt");
  const auto n = pos.size();
  std::vector<double> v(n), a(n), j(n), p(n), hp_out(n), i1(n), i2(n), i3(n);
  const SavgolFilter s0(225, 5, 0, 1.0 / 4000.0), s1(225, 5, 1, 1.0 / 4000.0), s2(225, 5, 2, 1.0 / 4000.0),
      s3(225, 5, 3, 1.0 / 4000.0);
  const auto hp = butter(5, 1.0, 4000.0, BandType::highpass);
  const int reps = 200;

  const double t_sg0 = best_us([&] { s0.apply(pos, p); }, reps);
  const double t_sg3 = best_us([&] { s3.apply(pos, j); }, reps);
  const double t_sff = best_us([&] { sosfiltfilt(hp, j, hp_out); }, reps);
  const double t_sf = best_us([&] { sosfilt(hp, j, hp_out); }, reps);
  const double t_ct = best_us([&] { cumulative_trapezoid(hp_out, 2.5e-4, i1); }, reps);
  const double t_welch = best_us([&] { g_sink = welch(j, 4000.0).pxx[3]; }, 50);
  WelchOptions whole;
  whole.nperseg = 12000;
  whole.nfft = 16384;
  const double t_welch_whole = best_us([&] { g_sink = welch(j, 4000.0, whole).pxx[3]; }, 50);
  const double t_design = best_us([&] { g_sink = butter(5, 1.0, 4000.0, BandType::highpass)[0].b0; }, 50);
  const double t_sgdesign = best_us([&] { g_sink = SavgolFilter(225, 5, 3, 2.5e-4).coeffs()[0]; }, 20);
  const double t_window = best_us([&] { g_sink = savgol_window_for_cutoff(4000.0, 30.0, 5); }, 5);
  // The estimator's per-axis chain: smooth position and take velocity,
  // acceleration and jerk; high-pass the jerk; integrate three times.
  const double t_chain = best_us(
      [&] {
        s0.apply(pos, p);
        s1.apply(pos, v);
        s2.apply(pos, a);
        s3.apply(pos, j);
        sosfiltfilt(hp, j, hp_out);
        cumulative_trapezoid(hp_out, 2.5e-4, i1);
        cumulative_trapezoid(i1, 2.5e-4, i2);
        cumulative_trapezoid(i2, 2.5e-4, i3);
      },
      reps);
  g_sink = p[100] + v[100] + a[100] + i3[100];
  std::printf("manip::dsp timings, n = %zu, best thread CPU time [us]\n", n);
  std::printf("  SavgolFilter(225,5,d=0).apply  %9.1f\n", t_sg0);
  std::printf("  SavgolFilter(225,5,d=3).apply  %9.1f\n", t_sg3);
  manip::dsp::detail::savgol_allow_avx2(false);
  std::printf("  ... portable (SSE2) kernel     %9.1f\n", best_us([&] { s3.apply(pos, j); }, reps));
  manip::dsp::detail::savgol_allow_avx2(true);
  std::printf("  sosfiltfilt(butter 5 hp)       %9.1f\n", t_sff);
  std::printf("  sosfilt(butter 5 hp)           %9.1f\n", t_sf);
  std::printf("  cumulative_trapezoid           %9.1f\n", t_ct);
  std::printf("  welch default                  %9.1f\n", t_welch);
  std::printf("  welch nperseg=n nfft=16384     %9.1f\n", t_welch_whole);
  std::printf("  butter(5, 1 Hz, hp) design     %9.1f\n", t_design);
  std::printf("  SavgolFilter(225,5,3) design   %9.1f\n", t_sgdesign);
  std::printf("  savgol_window_for_cutoff       %9.1f\n", t_window);
  std::printf("  chain: 4 savgol + sosfiltfilt + 3 cumtrapz %9.1f\n", t_chain);
  CHECK(t_chain > 0.0);
}
