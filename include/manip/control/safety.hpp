#pragma once
// Safety: condition checks (SafetyMonitor) and the controller's mode machine
// with latched faults (SafetyStateMachine). Both are plain, allocation-free
// classes driven once per cycle; docs/controller.md has the transition table.
//
// The software checks here are a second line: the hardware e-stop chain and
// the drives' safe torque off are the safety function; their status is
// monitored where the backend reports it (backend_status bits). An e-stop
// received over LCM is advisory (LCM is unauthenticated multicast).
#include <cstdint>
#include <vector>

#include "manip/common/types.hpp"
#include "manip/schema/codes.hpp"
#include "manip/control/config.hpp"
#include "manip/control/records.hpp"

namespace manip::control {

struct FaultDetail {
  std::uint32_t bit{0};  // first offending bit
  int axis{-1};
  double value{0.0};
  double limit{0.0};
  void set(std::uint32_t b, int ax, double v, double lim) {
    if (bit) return;  // keep the first
    bit = b;
    axis = ax;
    value = v;
    limit = lim;
  }
};

class SafetyMonitor {
 public:
  SafetyMonitor(const SafetyConfig& s, const CycleConfig& c, double sample_rate_hz);

  // Conditions present in this cycle's reading and timing (no latching here).
  std::uint32_t check_inputs(const SensorReading& in, bool overran, bool logger_failed, FaultDetail& d);
  // Conditions of this cycle's computed outputs.
  std::uint32_t check_outputs(const Vec2& f_motor_n, const Vec2& u_pert_n, const Vec2& x_ref_m, const Vec2& x_m,
                              FaultDetail& d) const;
  // Virtual walls on the admittance reference (spring-damper beyond wall_start).
  [[nodiscard]] Vec2 wall_force(const Vec2& x_ref_m, const Vec2& xd_ref_mps) const;
  // The safe law: zero force or a damping field, clamped to the motor limit.
  [[nodiscard]] Vec2 safe_force(const Vec2& xd_mps) const;
  // Forget the sample history (stale counters, overrun window), after a fault reset.
  void reset_history();

  [[nodiscard]] const SafetyConfig& config() const { return s_; }

 private:
  SafetyConfig s_;
  int consecutive_limit_;
  int per_second_limit_;
  std::int64_t window_cycles_;
  // stale detection
  bool have_seq_{false};
  std::uint64_t last_pos_seq_{0}, last_force_seq_{0};
  int pos_same_{0}, force_same_{0};
  // overrun policy
  int consecutive_{0};
  std::int64_t cycle_{0};
  std::vector<std::int64_t> overrun_ring_;  // cycles of the last per_second_limit overruns
  std::size_t ring_head_{0};
  std::size_t ring_fill_{0};
};

// Mode machine. Faults latch; only FAULT_RESET (operator) clears them, and only
// when no condition is present. Safe law in INIT, FAULT, ESTOP and STOPPED.
class SafetyStateMachine {
 public:
  [[nodiscard]] Mode mode() const { return mode_; }
  [[nodiscard]] std::uint32_t latched() const { return latched_; }
  [[nodiscard]] bool safe_law() const {
    return mode_ == Mode::kInit || mode_ == Mode::kFault || mode_ == Mode::kEStop || mode_ == Mode::kStopped;
  }
  [[nodiscard]] bool session_started() const { return session_started_; }

  // INIT -> IDLE on the first cycle without conditions.
  bool inputs_ok();
  // New condition bits: latch; -> FAULT (ESTOP and STOPPED stay). Returns the newly latched bits.
  std::uint32_t raise(std::uint32_t bits);
  // Advisory e-stop: latch kLcmEStop; -> ESTOP from any mode but STOPPED.
  void estop();
  // FAULT/ESTOP -> IDLE (no session yet) or PAUSED (session started), if nothing is present.
  Reject fault_reset(std::uint32_t present);
  Reject start_session();  // IDLE -> RUNNING
  Reject pause();          // RUNNING -> PAUSED
  Reject resume();         // PAUSED -> RUNNING
  Reject stop_session();   // IDLE/RUNNING/PAUSED -> DONE
  void session_done();     // RUNNING -> DONE (protocol finished)
  void shutdown();         // any -> STOPPED (terminal)

 private:
  Mode mode_{Mode::kInit};
  std::uint32_t latched_{0};
  bool session_started_{false};
};

}  // namespace manip::control
