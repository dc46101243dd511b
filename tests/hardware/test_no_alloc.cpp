// Proof that the real-time loop never allocates after start-up: the suite's
// allocation counter (tests/support/alloc_counter.hpp, GlobalAllocScope: any
// thread, only around the loop's cycles), over a simulated session driven
// cycle by cycle:
// backend read -> Controller::step -> backend write/display, with commands,
// perturbed trials, a fault and the orderly stop.
#include <catch2/catch.hpp>

#include "sanitized.hpp"

#include "alloc_counter.hpp"

#include "manip/command_t.hpp"
#include "manip/runtime/config.hpp"
#include "manip/control/controller.hpp"
#include "manip/runtime/session.hpp"
#include "manip/runtime/spsc_queue.hpp"
#include "manip/hardware/sim_backend.hpp"
#include "manip/trial_event_t.hpp"

using namespace manip::control;
using namespace manip::runtime;
using manip::Vec2;

TEST_CASE("the allocation counter is linked into this binary and counts", "[no_alloc]") {
  manip::test::AllocCounts got;
  {
    const manip::test::GlobalAllocScope c;
    auto* p = new int(3);
    asm volatile("" : : "r"(p) : "memory");  // the pointer escapes: new/delete cannot be elided
    delete p;
    got = c.counts();  // read before Catch's own allocations in CHECK
  }
  CHECK(got.news == 1);
  CHECK(got.deletes == 1);
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
  manip::hardware::SimBackend sim(cfg, cfg.sim, manip::hardware::make_sim_human(cfg, cfg.sim));
  sim.configure();
  sim.enable();
  RtCycle cycle(sim, ctl);

  long news = 0, deletes = 0;
  std::int64_t k = 0;
  long states = 0, onsets = 0, ends = 0, faults = 0, results = 0;
  auto drain = [&] {  // the consumers (logger/bus threads), outside the counted region
    LoopRecord r;
    while (log.try_pop(r)) {
      if (std::holds_alternative<manip::state_t>(r)) ++states;
      if (auto* e = std::get_if<TrialEventRecord>(&r)) {
        onsets += e->kind == manip::trial_event_t::ONSET;
        ends += e->kind == manip::trial_event_t::END;
      }
      faults += std::holds_alternative<FaultRecord>(r);
      results += std::holds_alternative<CommandResultRecord>(r);
    }
    while (bus.try_pop(r)) {
    }
  };
  auto command = [&](std::int8_t kind) {
    Command c;
    c.kind = kind;
    c.seq = k;
    c.start_shoulder_m = cfg.protocol.start_shoulder_m;
    c.goal_shoulder_m = cfg.protocol.goal_shoulder_m;
    REQUIRE(cmds.try_push(c));
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
      const manip::test::GlobalAllocScope counting;
      for (int i = 0; i < 256 && more; ++i, ++k) more = cycle.run_cycle(k, false);
      news += counting.counts().news;
      deletes += counting.counts().deletes;
    }
    drain();
  }
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
