#include "manip/canopen/virtual_bus.hpp"

#include <algorithm>

#include "manip/canopen/bus_load.hpp"

namespace manip::canopen {

VirtualBus::Endpoint& VirtualBus::attach() {
  auto ep = std::make_unique<Endpoint>();
  ep->bus_ = this;
  ep->index_ = static_cast<int>(endpoints_.size());
  endpoints_.push_back(std::move(ep));
  queues_.push_back(std::make_unique<Queue>());
  return *endpoints_.back();
}

void VirtualBus::deliver(int sender, const CanFrame& f, int64_t at_us) {
  for (std::size_t i = 0; i < queues_.size(); ++i) {
    if (static_cast<int>(i) == sender) continue;  // like SocketCAN: no echo to the sender
    Queue& q = *queues_[i];
    if (q.n >= kQueue) {
      ++overflowed_;
      continue;
    }
    q.items[q.n++] = Pending{at_us, seq_, f};
  }
  ++seq_;
}

bool VirtualBus::send_from(int sender, const CanFrame& f) {
  Injection inj;
  if (injector_) inj = injector_(sender, f);
  const int bits = frame_bits_worst(f.dlc);
  busy_bits_ += static_cast<uint64_t>(bits);
  int64_t done = now_us_;
  if (model_timing_) {
    // One frame at a time on the wire; arbitration order is ignored (FIFO).
    const double start = std::max<double>(static_cast<double>(now_us_), bus_free_at_us_);
    bus_free_at_us_ = start + bits * 1e6 / bitrate_;
    done = static_cast<int64_t>(bus_free_at_us_ + 0.999);
  }
  if (tap_) tap_(now_us_, sender, f);
  if (inj.drop) {
    ++dropped_;
    return true;  // lost on the wire; the sender cannot tell
  }
  deliver(sender, f, done + inj.delay_us);
  return true;
}

void VirtualBus::inject_error_frame(const CanFrame& f) {
  CanFrame e = f;
  e.flags |= CanFrame::kError;
  deliver(-1, e, now_us_);
}

std::size_t VirtualBus::receive_at(int ep, std::span<CanFrame> out) {
  Queue& q = *queues_[static_cast<std::size_t>(ep)];
  std::size_t n_out = 0;
  // Deliver due frames in (time, send order); keep the rest in place.
  while (n_out < out.size()) {
    std::size_t best = q.n;
    for (std::size_t i = 0; i < q.n; ++i) {
      if (q.items[i].at_us > now_us_) continue;
      if (best == q.n || q.items[i].at_us < q.items[best].at_us ||
          (q.items[i].at_us == q.items[best].at_us && q.items[i].seq < q.items[best].seq))
        best = i;
    }
    if (best == q.n) break;
    out[n_out++] = q.items[best].frame;
    q.items[best] = q.items[--q.n];
  }
  return n_out;
}

}  // namespace manip::canopen
