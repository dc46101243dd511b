// Timing statistics and the paced loop wrapper's overrun accounting.
#include <catch2/catch.hpp>

#include <chrono>
#include <thread>

#include "manip/runtime/rt_thread.hpp"
#include "manip/runtime/timing.hpp"

using namespace manip::control;
using namespace manip::runtime;

TEST_CASE("timing statistics: histogram percentiles and maxima", "[timing]") {
  TimingStats s;
  for (int i = 0; i < 1000; ++i) s.record((i % 100) * 1000 + 500, 2000);  // latency 0.5..99.5 us
  s.record(10'000'000, 300'000);                                          // 10 ms: over the range
  s.add_overrun();
  const auto t = s.snapshot();
  CHECK(t.cycles == 1001);
  CHECK(t.latency_p50_us == Approx(51.0));  // 50.5 us lies in the bin [50, 51)
  CHECK(t.latency_p99_us == Approx(99.0).margin(1.0));
  CHECK(t.latency_max_us == Approx(10000.0));
  CHECK(t.latency_over_range == 1);
  CHECK(t.compute_p50_us == Approx(2.1));  // 0.1 us bins, upper edge
  CHECK(t.compute_max_us == Approx(300.0));
  CHECK(t.overruns == 1);
  CHECK(t.summary().find("overruns 1") != std::string::npos);
}

namespace {
class SlowSometimes final : public CycleBody {
 public:
  SlowSometimes(int n, int every, std::chrono::microseconds slow) : n_(n), every_(every), slow_(slow) {}
  bool run_cycle(std::int64_t cycle, bool overran) override {
    if (cycle != next_) gapless_ = false;
    ++next_;
    overran_flags_ += overran;
    if (every_ > 0 && cycle % every_ == every_ - 1) {
      const auto until = std::chrono::steady_clock::now() + slow_;
      while (std::chrono::steady_clock::now() < until) {
      }
    }
    return cycle + 1 < n_;
  }
  int n_, every_;
  std::chrono::microseconds slow_;
  std::int64_t next_{0};
  bool gapless_{true};
  int overran_flags_{0};
};
}  // namespace

TEST_CASE("paced loop: cycles never skipped, overruns counted, late cycles flagged", "[timing][realtime]") {
  SECTION("catch up") {
    SlowSometimes body(400, 50, std::chrono::microseconds(600));  // 8 cycles of 600 us at 4 kHz
    TimingStats st;
    const auto n = run_paced(body, PacedOptions{250000, OverrunPolicy::kCatchUp, 4}, st);
    const auto t = st.snapshot();
    CHECK(n == 400);
    CHECK(body.gapless_);
    CHECK(t.cycles == 400);
    CHECK(t.overruns >= 8);                 // every slow cycle (plus possible scheduler hiccups)
    CHECK(body.overran_flags_ == t.overruns);  // the body is told about each one
  }
  SECTION("re-anchor counts the skipped periods") {
    SlowSometimes body(210, 50, std::chrono::microseconds(2000));  // 2 ms: 8 periods lost each time
    TimingStats st;
    run_paced(body, PacedOptions{250000, OverrunPolicy::kReanchor, 4}, st);
    const auto t = st.snapshot();
    CHECK(t.overruns >= 4);
    CHECK(t.skipped_periods >= 4 * 6);
    CHECK(body.gapless_);
  }
  SECTION("catch up too far behind re-anchors and counts") {
    SlowSometimes body(110, 50, std::chrono::microseconds(5000));  // 20 periods > max_catch_up 4
    TimingStats st;
    run_paced(body, PacedOptions{250000, OverrunPolicy::kCatchUp, 4}, st);
    CHECK(st.snapshot().skipped_periods >= 2 * 15);
  }
}

TEST_CASE("real-time detection reports the kernel", "[timing][realtime]") {
  const auto c = detect_rt();
  CHECK_FALSE(c.kernel_release.empty());
  CHECK(c.can_fifo(1) == (c.is_root || c.rtprio_limit >= 1));
}
