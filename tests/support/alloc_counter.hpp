#pragma once
// The one allocation counter of the test suite: it replaces the global
// operator new/delete (every form: plain, array, nothrow, aligned, sized) of
// any test executable that uses it, and counts
//   - per thread: allocations and frees made by the calling thread while a
//     ThreadAllocScope is alive (hot-path proofs of a function);
//   - globally: allocations and frees made by any thread while a
//     GlobalAllocScope is alive (the real-time thread's proof, where the
//     counted thread is not the test's).
// Linking it is by use: the replacement lives in alloc_counter.cpp, which the
// linker pulls from manip_testutil only into executables that use a scope.
#include <cstdint>

namespace manip::test {

struct AllocCounts {
  long news{0};
  long deletes{0};
};

class ThreadAllocScope {
 public:
  ThreadAllocScope();
  ~ThreadAllocScope();
  ThreadAllocScope(const ThreadAllocScope&) = delete;
  ThreadAllocScope& operator=(const ThreadAllocScope&) = delete;
  [[nodiscard]] AllocCounts counts() const;  // since construction, this thread
  [[nodiscard]] long news() const { return counts().news; }

 private:
  AllocCounts start_{};
};

class GlobalAllocScope {
 public:
  GlobalAllocScope();
  ~GlobalAllocScope();
  GlobalAllocScope(const GlobalAllocScope&) = delete;
  GlobalAllocScope& operator=(const GlobalAllocScope&) = delete;
  [[nodiscard]] AllocCounts counts() const;  // since construction, all threads
  [[nodiscard]] long news() const { return counts().news; }

 private:
  AllocCounts start_{};
};

}  // namespace manip::test
