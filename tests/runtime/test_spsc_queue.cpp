// runtime::SpscQueue: bounded, FIFO, and the loop's side (try_push/try_pop)
// never allocates, also when full.
#include <catch2/catch.hpp>

#include <thread>

#include "alloc_counter.hpp"
#include "manip/runtime/spsc_queue.hpp"

using manip::runtime::SpscQueue;

TEST_CASE("spsc queue: FIFO, bounded, no allocation on try_push/try_pop", "[spsc]") {
  SpscQueue<int> q(16);
  manip::control::Outbox<int>& out = q;  // the controller's view
  manip::control::Inbox<int>& in = q;
  manip::test::AllocCounts got;
  int pushed = 0, popped_sum = 0, rejected = 0;
  {
    const manip::test::ThreadAllocScope scope;
    for (int i = 0; i < 100; ++i) (out.try_push(i) ? ++pushed : ++rejected);
    int v = 0;
    while (in.try_pop(v)) popped_sum += v;
    got = scope.counts();
  }
  CHECK(got.news == 0);
  CHECK(got.deletes == 0);
  CHECK(pushed >= 16);  // at least the capacity asked for (moodycamel rounds up to a power of two)
  CHECK(pushed < 100);  // and bounded: the rest is refused, never grown
  CHECK(rejected == 100 - pushed);
  CHECK(popped_sum == pushed * (pushed - 1) / 2);  // 0..pushed-1, each once
  CHECK(q.size_approx() == 0u);
}

TEST_CASE("spsc queue: one producer and one consumer thread lose and reorder nothing", "[spsc]") {
  SpscQueue<long> q(64);
  constexpr long kN = 200000;
  std::thread producer([&] {
    for (long i = 0; i < kN; ++i)
      while (!q.try_push(i)) std::this_thread::yield();
  });
  long expected = 0;
  bool in_order = true;
  while (expected < kN) {
    long v = -1;
    if (q.try_pop(v)) {
      in_order = in_order && v == expected;
      ++expected;
    } else {
      std::this_thread::yield();
    }
  }
  producer.join();
  CHECK(in_order);
  CHECK(expected == kN);
}
