#pragma once
// In-process, deterministic CAN bus for tests and `manip_can_check --virtual`.
// Frames are serialised at the configured bitrate with their worst-case
// length (so an over-budget configuration really misses its deadlines), then
// delivered to every other endpoint. Per-frame drop/delay injection. Fixed
// capacity queues: no allocation after the endpoints are attached.
#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "manip/canopen/frame.hpp"

namespace manip::canopen {

class VirtualBus {
 public:
  struct Injection {
    bool drop = false;
    int64_t delay_us = 0;
  };
  // Decides per frame (sender endpoint index, frame) whether to drop/delay it.
  using Injector = std::function<Injection(int sender, const CanFrame&)>;
  using Tap = std::function<void(int64_t time_us, int sender, const CanFrame&)>;

  class Endpoint : public CanPort {
   public:
    bool send(const CanFrame& f) override { return bus_->send_from(index_, f); }
    std::size_t receive(std::span<CanFrame> out) override { return bus_->receive_at(index_, out); }
    int index() const { return index_; }

   private:
    friend class VirtualBus;
    VirtualBus* bus_ = nullptr;
    int index_ = 0;
  };

  explicit VirtualBus(uint32_t bitrate = 1000000, bool model_timing = true)
      : bitrate_(bitrate), model_timing_(model_timing) {}
  VirtualBus(const VirtualBus&) = delete;
  VirtualBus& operator=(const VirtualBus&) = delete;

  Endpoint& attach();
  void set_time(int64_t now_us) { now_us_ = now_us; }
  int64_t time() const { return now_us_; }
  void set_injector(Injector f) { injector_ = std::move(f); }
  void set_tap(Tap f) { tap_ = std::move(f); }
  // Deliver an error frame (SocketCAN-style) to every endpoint, e.g. bus-off.
  void inject_error_frame(const CanFrame& f);
  // Bus time occupied so far (bit times), for load measurements.
  uint64_t busy_bits() const { return busy_bits_; }
  uint64_t dropped() const { return dropped_; }
  uint64_t overflowed() const { return overflowed_; }

 private:
  static constexpr std::size_t kQueue = 512;
  struct Pending {
    int64_t at_us;
    uint64_t seq;
    CanFrame frame;
  };
  struct Queue {
    std::array<Pending, kQueue> items;
    std::size_t n = 0;
  };
  bool send_from(int sender, const CanFrame& f);
  std::size_t receive_at(int ep, std::span<CanFrame> out);
  void deliver(int sender, const CanFrame& f, int64_t at_us);

  uint32_t bitrate_;
  bool model_timing_;
  int64_t now_us_ = 0;
  double bus_free_at_us_ = 0;
  uint64_t seq_ = 0;
  uint64_t busy_bits_ = 0;
  uint64_t dropped_ = 0;
  uint64_t overflowed_ = 0;
  std::vector<std::unique_ptr<Endpoint>> endpoints_;
  std::vector<std::unique_ptr<Queue>> queues_;
  Injector injector_;
  Tap tap_;
};

}  // namespace manip::canopen
