#pragma once
// Timing statistics of the real-time loop: wake-up latency (actual wake time -
// deadline) and compute time (wake -> end of the cycle's work) as histograms,
// plus overruns and skipped periods. Written by the loop thread with relaxed
// atomics (single writer, no locks), read by any thread for health messages
// and the exit summary. Percentiles are the upper edge of the histogram bin.
#include <array>
#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

namespace manip::runtime {

struct TimingSnapshot {
  std::int64_t cycles{0};
  double latency_p50_us{0}, latency_p99_us{0}, latency_p999_us{0}, latency_max_us{0};
  double compute_p50_us{0}, compute_p99_us{0}, compute_p999_us{0}, compute_max_us{0};
  std::int64_t overruns{0};         // cycles that ended after the next deadline
  std::int64_t skipped_periods{0};  // periods dropped by re-anchoring (never silently: counted here)
  std::int64_t latency_over_range{0}, compute_over_range{0};
  [[nodiscard]] std::string summary() const;
};

class TimingStats {
 public:
  static constexpr int kLatencyBins = 5000;  // 1 us bins, 0..5 ms, + overflow
  static constexpr double kLatencyBinUs = 1.0;
  static constexpr int kComputeBins = 5000;  // 0.1 us bins, 0..500 us, + overflow
  static constexpr double kComputeBinUs = 0.1;

  TimingStats();
  // Loop thread only.
  void record(std::int64_t latency_ns, std::int64_t compute_ns);
  void record_compute(std::int64_t compute_ns);  // as-fast-as-possible runs: no deadline
  void add_overrun() { bump(overruns_); }
  void add_skipped(std::int64_t n) { skipped_.store(skipped_.load(std::memory_order_relaxed) + n, std::memory_order_relaxed); }
  // Any thread.
  [[nodiscard]] TimingSnapshot snapshot() const;
  // Wake-up latency histogram: counts per 1 us bin, the last entry = over range.
  [[nodiscard]] std::vector<std::int64_t> latency_histogram() const;
  void reset();

 private:
  static void bump(std::atomic<std::int64_t>& a) {
    a.store(a.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
  }
  std::array<std::atomic<std::int64_t>, kLatencyBins + 1> lat_{};
  std::array<std::atomic<std::int64_t>, kComputeBins + 1> comp_{};
  std::atomic<std::int64_t> lat_count_{0}, comp_count_{0}, lat_max_ns_{0}, comp_max_ns_{0};
  std::atomic<std::int64_t> overruns_{0}, skipped_{0};
};

}  // namespace manip::runtime
