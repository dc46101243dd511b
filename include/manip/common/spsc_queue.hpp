#pragma once
// The one lock-free single-producer/single-consumer queue of manip: every
// path out of (or into) the 4 kHz loop — loop -> logger, loop -> live bus,
// bus -> loop, the CAN backend's raw frames and fault notes. Wraps
// moodycamel::ReaderWriterQueue (Debian's libreaderwriterqueue-dev); the
// real-time side uses only try_push/try_pop (try_enqueue/try_dequeue), which
// never allocate after construction: the capacity is fixed up front, a full
// queue returns false and the caller counts the drop.
#include <cstddef>

#include <readerwriterqueue/readerwriterqueue.h>

namespace manip {

template <class T>
class SpscQueue {
 public:
  explicit SpscQueue(std::size_t capacity) : q_(capacity) {}
  SpscQueue(const SpscQueue&) = delete;
  SpscQueue& operator=(const SpscQueue&) = delete;

  bool try_push(const T& v) noexcept { return q_.try_enqueue(v); }
  bool try_pop(T& out) noexcept { return q_.try_dequeue(out); }
  // Grows the queue when full: non-real-time producers only (the bus thread's
  // health and rejections to the logger must not be lost).
  bool push_growing(const T& v) { return q_.enqueue(v); }
  [[nodiscard]] std::size_t size_approx() const { return q_.size_approx(); }
  [[nodiscard]] std::size_t capacity() const { return q_.max_capacity(); }

 private:
  moodycamel::ReaderWriterQueue<T> q_;
};

}  // namespace manip
