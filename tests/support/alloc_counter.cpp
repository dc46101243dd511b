#include "alloc_counter.hpp"

#include <atomic>
#include <cstdlib>
#include <new>

namespace {

thread_local int t_depth = 0;
thread_local long t_news = 0;
thread_local long t_deletes = 0;
std::atomic<int> g_depth{0};
std::atomic<long> g_news{0};
std::atomic<long> g_deletes{0};

void count_new() noexcept {
  if (t_depth > 0) ++t_news;
  if (g_depth.load(std::memory_order_relaxed) > 0) g_news.fetch_add(1, std::memory_order_relaxed);
}
void count_delete(void* p) noexcept {
  if (!p) return;
  if (t_depth > 0) ++t_deletes;
  if (g_depth.load(std::memory_order_relaxed) > 0) g_deletes.fetch_add(1, std::memory_order_relaxed);
}

// Every form pairs malloc/aligned_alloc with free, so ASan sees no mismatch
// (the nothrow form is used by std::stable_sort's temporary buffer).
void* plain(std::size_t n) noexcept {
  count_new();
  return std::malloc(n == 0 ? 1 : n);
}
void* aligned(std::size_t n, std::align_val_t al) noexcept {
  count_new();
  const auto a = static_cast<std::size_t>(al);
  return std::aligned_alloc(a, (n + a - 1) / a * a == 0 ? a : (n + a - 1) / a * a);
}
void release(void* p) noexcept {
  count_delete(p);
  std::free(p);
}

}  // namespace

namespace manip::test {

ThreadAllocScope::ThreadAllocScope() : start_{t_news, t_deletes} { ++t_depth; }
ThreadAllocScope::~ThreadAllocScope() { --t_depth; }
AllocCounts ThreadAllocScope::counts() const { return {t_news - start_.news, t_deletes - start_.deletes}; }

GlobalAllocScope::GlobalAllocScope() : start_{g_news.load(), g_deletes.load()} { g_depth.fetch_add(1); }
GlobalAllocScope::~GlobalAllocScope() { g_depth.fetch_sub(1); }
AllocCounts GlobalAllocScope::counts() const {
  return {g_news.load() - start_.news, g_deletes.load() - start_.deletes};
}

}  // namespace manip::test

void* operator new(std::size_t n) {
  if (void* p = plain(n)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  if (void* p = plain(n)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return plain(n); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return plain(n); }
void* operator new(std::size_t n, std::align_val_t a) {
  if (void* p = aligned(n, a)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n, std::align_val_t a) {
  if (void* p = aligned(n, a)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept { return aligned(n, a); }
void* operator new[](std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept { return aligned(n, a); }
void operator delete(void* p) noexcept { release(p); }
void operator delete[](void* p) noexcept { release(p); }
void operator delete(void* p, std::size_t) noexcept { release(p); }
void operator delete[](void* p, std::size_t) noexcept { release(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { release(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { release(p); }
void operator delete(void* p, std::align_val_t) noexcept { release(p); }
void operator delete[](void* p, std::align_val_t) noexcept { release(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { release(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { release(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { release(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { release(p); }
