// Proof that the real-time loop never allocates after start-up: a counting
// global operator new/delete (this file replaces them for the whole
// test_hardware binary; counting is enabled only on the calling thread, only
// around the loop's cycles), over a simulated session driven cycle by cycle:
// backend read -> Controller::step -> backend write/display, with commands,
// perturbed trials, a fault and the orderly stop.
#include <catch2/catch.hpp>

#include "sanitized.hpp"

#include <atomic>
#include <cstdlib>
#include <new>

#include "manip/command_t.hpp"
#include "manip/control/config.hpp"
#include "manip/control/controller.hpp"
#include "manip/hardware/runner.hpp"
#include "manip/hardware/sim_backend.hpp"
#include "manip/trial_event_t.hpp"

namespace {
thread_local bool g_counting = false;
std::atomic<long> g_news{0};
std::atomic<long> g_deletes{0};

void* counted_alloc(std::size_t n) {
  if (g_counting) g_news.fetch_add(1, std::memory_order_relaxed);
  void* p = std::malloc(n ? n : 1);
  if (!p) throw std::bad_alloc();
  return p;
}
void* counted_alloc_aligned(std::size_t n, std::align_val_t al) {
  if (g_counting) g_news.fetch_add(1, std::memory_order_relaxed);
  const auto a = static_cast<std::size_t>(al);
  void* p = std::aligned_alloc(a, (n + a - 1) / a * a);
  if (!p) throw std::bad_alloc();
  return p;
}
void counted_free(void* p) {
  if (p && g_counting) g_deletes.fetch_add(1, std::memory_order_relaxed);
  std::free(p);
}

struct CountScope {
  CountScope() { g_counting = true; }
  ~CountScope() { g_counting = false; }
};
}  // namespace

void* operator new(std::size_t n) { return counted_alloc(n); }
void* operator new[](std::size_t n) { return counted_alloc(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_alloc(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_alloc(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new(std::size_t n, std::align_val_t a) { return counted_alloc_aligned(n, a); }
void* operator new[](std::size_t n, std::align_val_t a) { return counted_alloc_aligned(n, a); }
void operator delete(void* p) noexcept { counted_free(p); }
void operator delete[](void* p) noexcept { counted_free(p); }
void operator delete(void* p, std::size_t) noexcept { counted_free(p); }
void operator delete[](void* p, std::size_t) noexcept { counted_free(p); }
void operator delete(void* p, std::align_val_t) noexcept { counted_free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { counted_free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { counted_free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { counted_free(p); }

using namespace manip::control;
using manip::Vec2;

TEST_CASE("the counting allocator counts (self-test)", "[no_alloc]") {
  const long before = g_news.load();
  {
    CountScope c;
    auto* p = new int(3);
    delete p;
  }
  CHECK(g_news.load() - before == 1);
}

TEST_CASE("zero allocations in the loop over a simulated session, cycle by cycle", "[no_alloc][session]") {
  const RtConfig base = load_rt_config(std::string(MANIP_SOURCE_DIR) + "/config/rt.yaml");
  // 8 movements (2 perturbed); 2 movements (1 perturbed) under the sanitizers
  const RtConfig cfg = kSanitized ? load_rt_config(std::string(MANIP_SOURCE_DIR) + "/config/rt.yaml",
                                                   {{"protocol.movements", "2"}, {"protocol.perturbed_trials", "1"}})
                                  : load_rt_config(std::string(MANIP_SOURCE_DIR) + "/config/rt.yaml", trials_overrides(base, 8));
  const int movements = cfg.protocol.movements;

  // --- start-up (allocations allowed) ---
  RecordQueue log(cfg.loop.log_queue_capacity), bus(cfg.loop.bus_queue_capacity);
  CommandQueue cmds(cfg.loop.command_queue_capacity);
  Controller ctl(cfg, {&log, &bus, &cmds}, ControllerOptions{true, false, 0, 1'700'000'000'000'000});
  manip::hardware::SimBackend sim(cfg, manip::hardware::make_sim_human(cfg));
  std::string err;
  REQUIRE(sim.start(err));
  manip::hardware::RtCycle cycle(sim, ctl);

  const long news0 = g_news.load(), deletes0 = g_deletes.load();
  std::int64_t k = 0;
  long states = 0, onsets = 0, ends = 0, faults = 0, results = 0;
  auto drain = [&] {  // the consumers (logger/bus threads), outside the counted region
    LoopRecord r;
    while (log.try_dequeue(r)) {
      if (std::holds_alternative<manip::state_t>(r)) ++states;
      if (auto* e = std::get_if<TrialEventRecord>(&r)) {
        onsets += e->kind == manip::trial_event_t::ONSET;
        ends += e->kind == manip::trial_event_t::END;
      }
      faults += std::holds_alternative<FaultRecord>(r);
      results += std::holds_alternative<CommandResultRecord>(r);
    }
    while (bus.try_dequeue(r)) {
    }
  };
  auto command = [&](std::int8_t kind) {
    Command c;
    c.kind = kind;
    c.seq = k;
    c.start_shoulder_m = cfg.protocol.start_shoulder_m;
    c.goal_shoulder_m = cfg.protocol.goal_shoulder_m;
    REQUIRE(cmds.try_enqueue(c));
  };
  bool more = true, commands_sent = false, fault_injected = false;
  std::int64_t reset_at = -1;
  while (more && k < 4'000'000) {
    if (!commands_sent && k >= 1000) {  // through the loop's command queue (the bus side allocates, not the loop)
      command(manip::command_t::PERTURBATIONS_OFF);
      command(manip::command_t::PERTURBATIONS_ON);
      command(manip::command_t::SET_TARGETS);
      command(manip::command_t::NEXT_TRIAL);
      commands_sent = true;
    }
    if (!fault_injected && ctl.protocol().counters().completed == movements - 2 && ctl.mode() == Mode::kRunning) {
      sim.inject.hw_estop = true;  // a fault: safe law, trial aborted
      fault_injected = true;
    }
    if (sim.inject.hw_estop && ctl.mode() == Mode::kFault) {
      sim.inject.hw_estop = false;  // the operator closes the e-stop chain ...
      reset_at = k + 1000;
    }
    if (reset_at >= 0 && k >= reset_at && ctl.mode() == Mode::kFault) {
      command(manip::command_t::FAULT_RESET);  // ... and resets
      reset_at = k + 4000;
    }
    if (ctl.mode() == Mode::kPaused) command(manip::command_t::RESUME);
    {
      CountScope counting;
      for (int i = 0; i < 256 && more; ++i, ++k) more = cycle.run_cycle(k, false);
    }
    drain();
  }
  const long news = g_news.load() - news0, deletes = g_deletes.load() - deletes0;
  INFO("cycles " << k << ", states " << states);
  CHECK(news == 0);
  CHECK(deletes == 0);
  CHECK_FALSE(more);  // the session ran to its end (stop when done)
  CHECK(states == k);
  CHECK(onsets == cfg.perturbed_count());
  CHECK(ends >= movements - 1);
  CHECK(faults >= 1);
  CHECK(results >= 6);
  CHECK(ctl.status().log_drops.load() == 0);
}
