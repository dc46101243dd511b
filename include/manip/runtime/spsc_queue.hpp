#pragma once
// The loop's queues: the one SPSC queue (common/spsc_queue.hpp) seen by the
// control law through its Outbox/Inbox interfaces.
#include <cstddef>

#include "manip/common/spsc_queue.hpp"
#include "manip/control/records.hpp"

namespace manip::runtime {

template <class T>
class SpscQueue final : public control::Outbox<T>, public control::Inbox<T> {
 public:
  explicit SpscQueue(std::size_t capacity) : q_(capacity) {}
  bool try_push(const T& v) noexcept override { return q_.try_push(v); }
  bool try_pop(T& out) noexcept override { return q_.try_pop(out); }
  bool push_growing(const T& v) { return q_.push_growing(v); }
  [[nodiscard]] std::size_t size_approx() const { return q_.size_approx(); }

 private:
  manip::SpscQueue<T> q_;
};

using RecordQueue = SpscQueue<control::LoopRecord>;
using CommandQueue = SpscQueue<control::Command>;

}  // namespace manip::runtime
