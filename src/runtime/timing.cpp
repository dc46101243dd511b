#include "manip/runtime/timing.hpp"

#include <algorithm>
#include <cstdio>

namespace manip::runtime {
namespace {

template <std::size_t N>
double percentile(const std::array<std::atomic<std::int64_t>, N>& h, std::int64_t total, double q, double bin_us) {
  if (total <= 0) return 0.0;
  const auto target = static_cast<std::int64_t>(q * static_cast<double>(total) + 0.999999);
  std::int64_t acc = 0;
  for (std::size_t i = 0; i < N; ++i) {
    acc += h[i].load(std::memory_order_relaxed);
    if (acc >= target) return static_cast<double>(i + 1) * bin_us;
  }
  return static_cast<double>(N) * bin_us;
}

}  // namespace

TimingStats::TimingStats() { reset(); }

void TimingStats::reset() {
  for (auto& b : lat_) b.store(0, std::memory_order_relaxed);
  for (auto& b : comp_) b.store(0, std::memory_order_relaxed);
  lat_count_ = comp_count_ = lat_max_ns_ = comp_max_ns_ = overruns_ = skipped_ = 0;
}

void TimingStats::record_compute(std::int64_t compute_ns) {
  if (compute_ns < 0) compute_ns = 0;
  const auto bin = std::min<std::int64_t>(static_cast<std::int64_t>(compute_ns / (kComputeBinUs * 1000.0)), kComputeBins);
  bump(comp_[static_cast<std::size_t>(bin)]);
  bump(comp_count_);
  if (compute_ns > comp_max_ns_.load(std::memory_order_relaxed)) comp_max_ns_.store(compute_ns, std::memory_order_relaxed);
}

void TimingStats::record(std::int64_t latency_ns, std::int64_t compute_ns) {
  if (latency_ns < 0) latency_ns = 0;
  const auto bin = std::min<std::int64_t>(static_cast<std::int64_t>(latency_ns / (kLatencyBinUs * 1000.0)), kLatencyBins);
  bump(lat_[static_cast<std::size_t>(bin)]);
  bump(lat_count_);
  if (latency_ns > lat_max_ns_.load(std::memory_order_relaxed)) lat_max_ns_.store(latency_ns, std::memory_order_relaxed);
  record_compute(compute_ns);
}

TimingSnapshot TimingStats::snapshot() const {
  TimingSnapshot s;
  const auto nl = lat_count_.load(std::memory_order_relaxed);
  const auto nc = comp_count_.load(std::memory_order_relaxed);
  s.cycles = nc;
  s.latency_p50_us = percentile(lat_, nl, 0.50, kLatencyBinUs);
  s.latency_p99_us = percentile(lat_, nl, 0.99, kLatencyBinUs);
  s.latency_p999_us = percentile(lat_, nl, 0.999, kLatencyBinUs);
  s.latency_max_us = static_cast<double>(lat_max_ns_.load(std::memory_order_relaxed)) / 1000.0;
  s.compute_p50_us = percentile(comp_, nc, 0.50, kComputeBinUs);
  s.compute_p99_us = percentile(comp_, nc, 0.99, kComputeBinUs);
  s.compute_p999_us = percentile(comp_, nc, 0.999, kComputeBinUs);
  s.compute_max_us = static_cast<double>(comp_max_ns_.load(std::memory_order_relaxed)) / 1000.0;
  s.overruns = overruns_.load(std::memory_order_relaxed);
  s.skipped_periods = skipped_.load(std::memory_order_relaxed);
  s.latency_over_range = lat_[kLatencyBins].load(std::memory_order_relaxed);
  s.compute_over_range = comp_[kComputeBins].load(std::memory_order_relaxed);
  return s;
}

std::vector<std::int64_t> TimingStats::latency_histogram() const {
  std::vector<std::int64_t> h(lat_.size());
  for (std::size_t i = 0; i < lat_.size(); ++i) h[i] = lat_[i].load(std::memory_order_relaxed);
  return h;
}

std::string TimingSnapshot::summary() const {
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "cycles %lld; wake-up latency p50 %.0f us, p99 %.0f us, p99.9 %.0f us, max %.1f us; "
                "compute p50 %.1f us, p99 %.1f us, p99.9 %.1f us, max %.1f us; overruns %lld; skipped periods %lld",
                static_cast<long long>(cycles), latency_p50_us, latency_p99_us, latency_p999_us, latency_max_us,
                compute_p50_us, compute_p99_us, compute_p999_us, compute_max_us, static_cast<long long>(overruns),
                static_cast<long long>(skipped_periods));
  return buf;
}

}  // namespace manip::runtime
