#pragma once
// A session as a stream of typed messages: what a log file holds, what the
// simulator produces and what the estimator consumes. Logs, simulations and
// live captures all go through this one interface, so every tool works on
// simulated sessions exactly as on lab logs.
#include <cstdint>
#include <string>

#include "manip/fault_t.hpp"
#include "manip/impedance_truth_t.hpp"
#include "manip/session_t.hpp"
#include "manip/state_t.hpp"
#include "manip/trial_event_t.hpp"
#include "manip/logging/event_log.hpp"

namespace manip::logging {

class SessionHandler {
 public:
  virtual ~SessionHandler() = default;
  virtual void on_session(const manip::session_t& /*msg*/) {}
  virtual void on_state(const manip::state_t& /*msg*/) {}
  virtual void on_trial_event(const manip::trial_event_t& /*msg*/) {}
  virtual void on_fault(const manip::fault_t& /*msg*/) {}
  // Simulators only: the unperturbed twin of a perturbed trial (same cycles) and the ground truth.
  virtual void on_truth_state(const manip::state_t& /*msg*/) {}
  virtual void on_truth_impedance(const manip::impedance_truth_t& /*msg*/) {}
  // Something in the input could not be used: one line naming what and where.
  virtual void on_warning(const std::string& /*message*/) {}
};

// Writes the stream into an LCM event log (channels from common/channels.hpp).
class LogWritingHandler final : public SessionHandler {
 public:
  explicit LogWritingHandler(const std::string& path);  // throws std::runtime_error if it cannot create the file
  void on_session(const manip::session_t& msg) override;
  void on_state(const manip::state_t& msg) override;
  void on_trial_event(const manip::trial_event_t& msg) override;
  void on_fault(const manip::fault_t& msg) override;
  void on_truth_state(const manip::state_t& msg) override;
  void on_truth_impedance(const manip::impedance_truth_t& msg) override;
  // Throws std::runtime_error with the writer's error if anything failed.
  void close();

 private:
  void check();
  EventLogWriter w_;
  std::int64_t last_utime_{0};
};

struct LogReadSummary {
  ReadDiagnostics diagnostics;
  std::uint64_t undecodable{0};       // events on manip channels that failed to decode
  std::uint64_t unknown_channels{0};  // events on other channels (ignored)
  bool session_seen{false};           // a decodable session message was handed to the handler
};

// Streams a log into a handler. Throws std::runtime_error (message names the
// file) if the file cannot be opened, is not an LCM log, or its session
// message has a schema version this build does not know. Damage inside the
// file (garbage, corrupted length fields, truncated tail, undecodable events
// including a damaged session message) is reported through handler.on_warning
// as "<file>: byte <offset> (<channel>): ...", and reading continues. Every
// payload is decoded with safe_decode (safe_decode.hpp). An exception thrown
// by the handler is rethrown as std::runtime_error prefixed with the file,
// the byte offset and the channel of the event being handled.
LogReadSummary read_log(const std::string& path, SessionHandler& handler);

}  // namespace manip::logging
