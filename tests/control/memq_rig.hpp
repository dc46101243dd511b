#pragma once
// The controller and the LCM bus wired together on memq:// (in-process LCM):
// the rig of the command-path tests (tests/runtime/test_commands.cpp) and the
// display-target test (tests/display/test_targets.cpp). Queue sizes as in
// manip_rt's defaults for one test's worth of traffic.
#include <catch2/catch.hpp>

#include <lcm/lcm-cpp.hpp>

#include <memory>
#include <string>
#include <vector>

#include "manip/control/controller.hpp"
#include "manip/runtime/bus.hpp"

namespace test_support {

struct MemqRig {
  manip::runtime::RecordQueue log{1 << 16}, busq{4096};
  manip::runtime::CommandQueue cmds{64};
  manip::control::Controller ctl;
  manip::runtime::Bus bus;

  explicit MemqRig(const manip::runtime::RtConfig& cfg)
      : ctl(cfg, {&log, &busq, &cmds}, manip::control::ControllerOptions{false, false, 0, 0}),
        bus(cfg, manip::runtime::Bus::Links{&busq, &cmds, &ctl.status(), nullptr, nullptr}) {
    std::string err;
    REQUIRE(bus.open("memq://", err));
  }

  // Every message of type T published on `channel`, in order (the vector
  // must outlive the rig's dispatching).
  template <class T>
  void collect(const std::string& channel, std::vector<T>& out) {
    bus.lcm()->subscribe(channel, &Collector<T>::on, new_collector(out));
  }
  void poll(int n = 10) {
    for (int i = 0; i < n; ++i) bus.poll(0);
  }

 private:
  template <class T>
  struct Collector {
    std::vector<T>* out;
    void on(const lcm::ReceiveBuffer*, const std::string&, const T* m) { out->push_back(*m); }
  };
  template <class T>
  Collector<T>* new_collector(std::vector<T>& out) {
    auto c = std::make_shared<Collector<T>>(Collector<T>{&out});
    keep_.push_back(c);
    return c.get();
  }
  std::vector<std::shared_ptr<void>> keep_;
};

}  // namespace test_support
