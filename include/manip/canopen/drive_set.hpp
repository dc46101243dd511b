#pragma once
// CanDriveSet: the façade the `can` hardware backend will use (after the
// architecture refactor): configure -> enable -> {read -> update -> write}
// at 4 kHz -> disable -> shutdown. One Master per bus (one bus per drive or
// a shared bus). read()/write() are allocation-free; the lifecycle calls
// loop over a Ticker that waits one control period (real time) or advances
// simulated time (tests) and returns the current time in microseconds.
#include <array>
#include <functional>
#include <memory>
#include <vector>

#include "manip/canopen/bus_load.hpp"
#include "manip/canopen/frame_recorder.hpp"
#include "manip/canopen/master.hpp"
#include "manip/common/types.hpp"

namespace manip::canopen {

struct DriveSetFeedback {
  Vec2 position_m = Vec2::Zero();    // workspace frame
  Vec2 velocity_mps = Vec2::Zero();  // workspace frame (0x606C if mapped, else from positions per SYNC)
  std::array<uint16_t, 2> statusword{};
  std::array<uint32_t, 2> digital_inputs{};  // 0x60FD (0 if not mapped)
  std::array<cia402::State, 2> state{cia402::State::NotReadyToSwitchOn, cia402::State::NotReadyToSwitchOn};
  bool enabled = false;  // every axis in Operation enabled
  bool faulted = false;  // a master is Faulted/Failed: the command is ignored, drives disabled
};

class CanDriveSet {
 public:
  using Ticker = std::function<int64_t()>;
  // ports: one per cfg.buses entry, same order; not owned.
  CanDriveSet(const CanConfig& cfg, std::vector<CanPort*> ports);

  std::vector<BusBudget> budgets() const { return compute_budgets(cfg_); }
  Error configure(const Ticker& tick);  // NMT reset, SDO start-up, NMT start; drives disabled
  Error enable(const Ticker& tick);     // CiA 402 to Operation enabled, zero torque preloaded
  const DriveSetFeedback& read(int64_t now_us);
  void write(const Vec2& force_n);      // workspace-frame force command for this cycle
  Error disable(const Ticker& tick);
  Error shutdown(const Ticker& tick);
  // Operator acknowledge: every Faulted bus gets its one edge on controlword
  // bit 7 (Master::request_fault_reset). False if a bus needs a restart.
  bool request_fault_reset();
  // Every faulted bus would accept request_fault_reset() (false if none is faulted).
  bool fault_acknowledgeable() const;
  // Real-time re-enable after an acknowledged fault: CiA 402 transitions 2,
  // 3, 4 driven by write() with zero target torque preloaded, the same path
  // as enable() without its waiting loop. Ignored while faulted.
  void request_enable() {
    if (!faulted()) enable_wanted_ = true;
  }
  bool enable_wanted() const { return enable_wanted_; }
  // Real-time disarm: stop walking / holding the drives towards Operation
  // enabled (the next write() commands Disable voltage, transition 9/7/10).
  // E.g. an enable that timed out: it must not complete later by itself.
  void cancel_enable() { enable_wanted_ = false; }
  // Real-time stop of the whole set with a reason (e.g. the backend saw the
  // e-stop chain open): every running bus enters its safe state in this call
  // (Disable voltage + zero torque + SYNC, flushed now), the enable intent is
  // dropped, and only an operator reset (request_fault_reset(), then
  // request_enable()) re-enables. No-op if already faulted.
  void stop(const Error& reason);
  // Reset attempts (all buses) that left a drive in Fault.
  uint32_t fault_resets_failed() const;

  // Every frame sent (accepted by the port) and received from now on goes to
  // `r` (not owned; nullptr = off). Call before configure().
  void set_recorder(FrameRecorder* r) { recorder_ = r; }

  bool faulted() const;
  Error error() const;                  // reason of the first faulted/failed bus ({} if none)
  std::size_t bus_count() const { return masters_.size(); }
  Master& master(std::size_t bus) { return *masters_[bus]; }
  const AxisScaling& scaling(int axis) const { return axes_[std::size_t(axis)].scale; }

 private:
  struct Axis {
    std::size_t bus = 0;
    std::size_t slot = 0;
    AxisScaling scale;
    int32_t prev_counts = 0;
    uint32_t prev_tpdos = 0;
    bool have_prev = false;
    bool has_velocity = false;
  };
  Error run_until(const Ticker& tick, int64_t timeout_us, const std::function<bool()>& done, ErrorCode on_timeout);
  void flush(std::size_t bus, FrameBuffer& tx);
  void propagate_fault(bool discard_pending);

  CanConfig cfg_;
  std::vector<CanPort*> ports_;
  std::vector<std::unique_ptr<Master>> masters_;
  std::array<Axis, 2> axes_{};
  int n_axes_ = 0;
  bool enable_wanted_ = false;
  bool was_faulted_ = false;
  int64_t now_us_ = 0;
  DriveSetFeedback fb_;
  std::vector<FrameBuffer> tx_;  // one per bus, preallocated
  std::vector<uint8_t> tx_failed_;  // a send was refused (queue full / interface down)
  std::array<CanFrame, 64> rx_{};
  FrameRecorder* recorder_ = nullptr;
};

}  // namespace manip::canopen
