#pragma once
// What goes in and out of the 4 kHz loop. Everything here is trivially
// copyable and fixed-size: the loop hands these to the Outbox/Inbox interfaces
// below, which the runtime implements with preallocated lock-free
// single-producer/single-consumer queues (runtime/spsc_queue.hpp), so the loop
// never allocates, locks or does I/O. The non-real-time threads turn them into
// LCM messages (strings are built there, from the codes).
#include <cstdint>
#include <variant>

#include "manip/common/types.hpp"
#include "manip/schema/codes.hpp"
#include "manip/state_t.hpp"

namespace manip::control {

// One reading of the backend at the start of a cycle (workspace frame, SI).
struct SensorReading {
  Vec2 x_workspace_m{Vec2::Zero()};          // stage encoders
  Vec2 xd_workspace_mps{Vec2::Zero()};       // drive velocity estimate
  Vec2 f_sensor_workspace_n{Vec2::Zero()};   // force of the hand side on the handle's sensor
  std::uint64_t position_seq{0};             // increments with every fresh position sample
  std::uint64_t force_seq{0};                // increments with every fresh force sample
  std::uint32_t status{0};                   // backend_status bits
};

// What the lab's visual feedback shows (also on the live bus in state_t and
// trial events). Only simulated backends consume it: their simulated
// participant "watches the screen".
struct DisplayCue {
  Phase phase{Phase::kNone};
  std::int32_t trial{-1};
  Vec2 start_shoulder_m{Vec2::Zero()};
  Vec2 goal_shoulder_m{Vec2::Zero()};
};

// The loop's output for the backend.
struct ActuatorCommand {
  Vec2 f_motor_n{Vec2::Zero()};  // per stage, workspace axes
  bool enable{false};            // drives enabled (false: disable / quick stop)
  bool send{false};              // write to the drives this cycle (drive tick, or a safe-law change)
  DisplayCue cue{};
};

// A command from a lab tool after the bus thread's validation (ranges, units).
struct Command {
  std::int64_t seq{0};
  std::int8_t kind{0};  // command_t kinds
  Vec2 start_shoulder_m{Vec2::Zero()};
  Vec2 goal_shoulder_m{Vec2::Zero()};
};

struct TrialEventRecord {
  std::int64_t utime{0};
  std::int64_t cycle{0};
  std::int32_t trial{-1};
  std::int8_t kind{0};  // trial_event_t kinds
  bool perturbed{false};
  Vec2 start_shoulder_m{Vec2::Zero()};
  Vec2 goal_shoulder_m{Vec2::Zero()};
  double pert_angle_rad{0.0};
  double pert_amplitude_n{0.0};
  double pert_duration_s{0.0};
  AbortReason reason{AbortReason::kNone};
  bool dropped{false};  // ABORT of a perturbed trial that exceeded max_requeues (not re-queued)
};

struct FaultRecord {
  std::int64_t utime{0};
  std::int64_t cycle{0};
  std::uint32_t new_flags{0};    // bits raised this cycle
  std::uint32_t fault_flags{0};  // all latched bits after this cycle
  Mode mode{Mode::kFault};
  int axis{-1};                  // axis of the first offending value, -1 if none
  double value{0.0};             // offending value (SI) of the first new bit
  double limit{0.0};             // its limit
};

struct CommandResultRecord {
  std::int64_t utime{0};
  std::int64_t seq{0};
  std::int8_t kind{0};
  bool accepted{false};
  Reject reason{Reject::kNone};
  Mode mode_after{Mode::kInit};
  std::uint32_t detail{0};  // for kConditionPresent: fault bits still present
};

using LoopRecord = std::variant<manip::state_t, TrialEventRecord, FaultRecord, CommandResultRecord>;
// The loop's side of a bounded queue: never blocks, never allocates; false
// when full (the caller counts the drop) or empty.
template <class T>
class Outbox {
 public:
  virtual ~Outbox() = default;
  virtual bool try_push(const T& v) noexcept = 0;
};
template <class T>
class Inbox {
 public:
  virtual ~Inbox() = default;
  virtual bool try_pop(T& out) noexcept = 0;
};
using RecordSink = Outbox<LoopRecord>;
using CommandSource = Inbox<Command>;

}  // namespace manip::control
