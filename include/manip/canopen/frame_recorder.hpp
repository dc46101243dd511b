#pragma once
// Raw CAN traffic recording (candump-like) for the session log: the drive
// set hands every frame it sends or receives to record() in the real-time
// thread (a copy into a preallocated lock-free ring, no allocation, no
// lock); another thread (the logger) pops them. A full ring drops the frame
// and counts it: recording never slows the loop down.
#include <atomic>
#include <cstdint>

#include "manip/canopen/frame.hpp"
#include "manip/common/spsc_queue.hpp"

namespace manip::canopen {

struct RecordedFrame {
  int64_t cycle = -1;  // loop cycle that handled it; -1 = outside the loop (start-up, shutdown)
  int64_t t_us = 0;    // the master's clock
  CanFrame frame;
  uint8_t iface = 0;   // bus index (CanConfig::buses order)
  bool tx = false;     // sent by the master (else received)
};

class FrameRecorder {
 public:
  explicit FrameRecorder(std::size_t capacity) : ring_(capacity) {}
  // Producer (the thread that runs the drive set).
  void set_cycle(int64_t cycle) noexcept { cycle_ = cycle; }
  void record(int64_t t_us, uint8_t iface, bool tx, const CanFrame& f) noexcept {
    RecordedFrame r;
    r.cycle = cycle_;
    r.t_us = t_us;
    r.frame = f;
    r.iface = iface;
    r.tx = tx;
    if (!ring_.try_push(r)) dropped_.fetch_add(1, std::memory_order_relaxed);
  }
  // Consumer.
  bool pop(RecordedFrame& out) noexcept { return ring_.try_pop(out); }
  [[nodiscard]] int64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }
  [[nodiscard]] std::size_t capacity() const { return ring_.capacity(); }
  [[nodiscard]] std::size_t size_approx() const { return ring_.size_approx(); }

 private:
  SpscQueue<RecordedFrame> ring_;
  int64_t cycle_ = -1;
  std::atomic<int64_t> dropped_{0};
};

}  // namespace manip::canopen
