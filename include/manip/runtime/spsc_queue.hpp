#pragma once
// The one lock-free single-producer/single-consumer queue of manip (the loop
// -> logger, loop -> live bus, bus -> loop paths). Wraps
// moodycamel::ReaderWriterQueue, using only try_enqueue/try_dequeue, which
// never allocate after construction: the capacity is fixed up front.
#include <cstddef>

#include <readerwriterqueue/readerwriterqueue.h>

#include "manip/control/records.hpp"

namespace manip::runtime {

template <class T>
class SpscQueue final : public control::Outbox<T>, public control::Inbox<T> {
 public:
  explicit SpscQueue(std::size_t capacity) : q_(capacity) {}
  bool try_push(const T& v) noexcept override { return q_.try_enqueue(v); }
  bool try_pop(T& out) noexcept override { return q_.try_dequeue(out); }
  // Grows the queue when full: non-real-time producers only (the bus thread's
  // health and rejections to the logger must not be lost).
  bool push_growing(const T& v) { return q_.enqueue(v); }
  [[nodiscard]] std::size_t size_approx() const { return q_.size_approx(); }

 private:
  moodycamel::ReaderWriterQueue<T> q_;
};

using RecordQueue = SpscQueue<control::LoopRecord>;
using CommandQueue = SpscQueue<control::Command>;

}  // namespace manip::runtime
