#pragma once
// A fixed-capacity lock-free single-producer/single-consumer ring for
// trivially copyable values: the real-time thread pushes (never allocates,
// never blocks; false when full, the caller counts the drop), one other
// thread pops. Capacity is rounded up to a power of two and allocated once,
// in the constructor. (The runtime's SpscQueue wraps readerwriterqueue; this
// one lives below it so the canopen and hardware modules need no extra
// dependency.)
#include <atomic>
#include <cstddef>
#include <memory>
#include <new>
#include <type_traits>

namespace manip::canopen {

template <class T>
class SpscRing {
  static_assert(std::is_trivially_copyable_v<T>, "SpscRing holds plain values");

 public:
  explicit SpscRing(std::size_t capacity) {
    std::size_t c = 2;
    while (c < capacity) c <<= 1;
    mask_ = c - 1;
    buf_ = std::make_unique<T[]>(c);
  }
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  // Producer thread only.
  bool try_push(const T& v) noexcept {
    const std::size_t t = tail_.load(std::memory_order_relaxed);
    if (t - head_.load(std::memory_order_acquire) > mask_) return false;  // full
    buf_[t & mask_] = v;
    tail_.store(t + 1, std::memory_order_release);
    return true;
  }
  // Consumer thread only.
  bool try_pop(T& out) noexcept {
    const std::size_t h = head_.load(std::memory_order_relaxed);
    if (h == tail_.load(std::memory_order_acquire)) return false;  // empty
    out = buf_[h & mask_];
    head_.store(h + 1, std::memory_order_release);
    return true;
  }
  [[nodiscard]] std::size_t capacity() const { return mask_ + 1; }
  [[nodiscard]] std::size_t size_approx() const {
    return tail_.load(std::memory_order_acquire) - head_.load(std::memory_order_acquire);
  }

 private:
  std::unique_ptr<T[]> buf_;
  std::size_t mask_{0};
  alignas(64) std::atomic<std::size_t> head_{0};  // next to pop (consumer)
  alignas(64) std::atomic<std::size_t> tail_{0};  // next to push (producer)
};

}  // namespace manip::canopen
