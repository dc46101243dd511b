#pragma once
// The live LCM bus (non-real-time thread): publishes decimated state
// (MANIP_STATE_LIVE), trial events (MANIP_TRIAL), command results
// (MANIP_COMMAND_STATUS), health/timing (MANIP_HEALTH), the session message
// (MANIP_SESSION) and fault records (MANIP_FAULT, via the logger's fault sink);
// receives commands (MANIP_COMMAND).
//
// Commands are checked in two stages: here (decodable, known kind, finite
// values in range, targets inside the walls, trigger between the targets, the
// loop's queue not full) and in the loop (whether the controller's mode allows
// it: the loop is the only authority on its state). Every command is answered
// on MANIP_COMMAND_STATUS with its seq; undecodable payloads are answered with
// seq -1. The loop takes at most loop.max_commands_per_cycle commands per
// cycle, so a flood or garbage on the channel cannot disturb it.
#include <atomic>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>

#include "manip/command_status_t.hpp"
#include "manip/command_t.hpp"
#include "manip/common/frames.hpp"
#include "manip/runtime/config.hpp"
#include "manip/control/controller.hpp"
#include "manip/runtime/logger.hpp"
#include "manip/control/records.hpp"
#include "manip/runtime/spsc_queue.hpp"
#include "manip/runtime/timing.hpp"
#include "manip/fault_t.hpp"
#include "manip/health_t.hpp"
#include "manip/session_t.hpp"

namespace lcm {
class LCM;
}  // namespace lcm
struct _lcm_recv_buf_t;
struct _lcm_subscription_t;

namespace manip::runtime {

struct CommandLimits {
  WorkspaceToShoulder frame{};
  double wall_start_m{0.135};
  double target_radius_m{0.01};
  double trigger_x2_shoulder_m{0.40};
  bool require_trigger_between{true};  // false when the session has no perturbed trials
  static CommandLimits from_config(const RtConfig& cfg);
};

// Range/unit validation of a decoded command (no state checks).
control::Reject validate_command(const manip::command_t& c, const CommandLimits& lim);

// Decode + validate + hand to the loop. Usable without LCM (tests).
class CommandGate {
 public:
  CommandGate(CommandQueue& q, const CommandLimits& lim) : q_(q), lim_(lim) {}
  // nullopt: handed to the loop (the loop answers). Otherwise the rejection to publish.
  std::optional<manip::command_status_t> submit(const void* data, int size, std::int64_t utime_now,
                                                std::int8_t mode_now);
  [[nodiscard]] std::int64_t received() const { return received_; }
  [[nodiscard]] std::int64_t rejected() const { return rejected_; }

 private:
  CommandQueue& q_;
  CommandLimits lim_;
  std::int64_t received_{0}, rejected_{0};
};

// Datagrams the kernel dropped on this process's UDP sockets (receive buffer
// full), from /proc/self/net/udp: under a command flood the packets lost
// before manip_rt could read them (LCM's udpm socket also receives manip_rt's
// own publications, so this counts all of them). -1 is never returned; 0 if
// the table is unreadable.
std::int64_t udp_socket_drops();

class Bus {
 public:
  struct Links {
    RecordQueue* from_loop{nullptr};
    CommandQueue* to_loop{nullptr};
    const control::ControllerStatus* status{nullptr};
    const TimingStats* timing{nullptr};
    AuxQueue* to_logger{nullptr};  // health and bus-side rejections into the log
  };
  Bus(const RtConfig& cfg, Links links);
  ~Bus();
  Bus(const Bus&) = delete;
  Bus& operator=(const Bus&) = delete;

  // Creates the LCM instance and subscribes. False + err (naming the URL and the
  // usual cause) if LCM cannot be created.
  bool open(const std::string& url, std::string& err);
  void publish_session(const manip::session_t& s);
  void publish_fault(const manip::fault_t& f);  // any thread
  // One iteration: handle incoming messages (up to timeout_ms), publish what the loop produced, health when due.
  void poll(int timeout_ms);
  void run(const std::atomic<bool>& stop);
  void publish_health();

  [[nodiscard]] lcm::LCM* lcm() { return lcm_.get(); }
  [[nodiscard]] const CommandGate& gate() const { return gate_; }
  [[nodiscard]] std::int64_t published_states() const { return published_states_; }
  [[nodiscard]] std::int64_t publish_errors() const { return publish_errors_; }
  // Commands refused on the bus side (undecodable, invalid, loop queue full)
  // plus commands whose handling threw (counted, never propagated).
  [[nodiscard]] std::int64_t command_rejects() const {
    return gate_.rejected() + handler_errors_.load(std::memory_order_relaxed);
  }
  [[nodiscard]] std::int64_t commands_received() const { return gate_.received(); }

 private:
  static void c_on_command(const _lcm_recv_buf_t* rbuf, const char* channel, void* self);
  void on_command(const void* data, int size);
  void drain_loop();
  template <class Msg>
  void publish(const char* channel, const Msg& m);
  // MANIP_TARGETS (participant display): on every change of cue_ and at ~1 Hz.
  void track_targets(const control::LoopRecord& r);
  void publish_targets();

  static constexpr int kMaxMessagesPerPoll = 256;
  RtConfig cfg_;
  Links links_;
  std::unique_ptr<lcm::LCM> lcm_;
  _lcm_subscription_t* sub_{nullptr};  // C API: no C++ subscription wrapper
  CommandGate gate_;
  std::int64_t next_health_ns_{0};
  std::int64_t published_states_{0};
  std::int64_t publish_errors_{0};
  std::atomic<std::int64_t> handler_errors_{0};
  control::DisplayCue cue_{};              // what the display shows, as last published
  std::int64_t cue_cycle_{0}, cue_seq_{-1};
  std::deque<control::Command> pending_targets_;  // SET_TARGETS handed to the loop, awaiting its answer
  std::int64_t next_targets_ns_{0};
};

}  // namespace manip::runtime
