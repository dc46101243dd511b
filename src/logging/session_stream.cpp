#include "manip/logging/session_stream.hpp"

#include <stdexcept>
#include <string_view>

#include "manip/common/channels.hpp"

namespace manip::logging {

LogWritingHandler::LogWritingHandler(const std::string& path) {
  if (!w_.open(path)) throw std::runtime_error(w_.error());
}

void LogWritingHandler::check() {
  if (!w_.ok()) throw std::runtime_error(w_.error());
}

void LogWritingHandler::on_session(const manip::session_t& msg) {
  last_utime_ = msg.utime_start;
  w_.write_message(channels::kSession, msg.utime_start, msg);
  check();
}
void LogWritingHandler::on_state(const manip::state_t& msg) {
  last_utime_ = msg.utime;
  w_.write_message(channels::kState, msg.utime, msg);
  check();
}
void LogWritingHandler::on_trial_event(const manip::trial_event_t& msg) {
  w_.write_message(channels::kTrial, msg.utime, msg);
  check();
}
void LogWritingHandler::on_fault(const manip::fault_t& msg) {
  w_.write_message(channels::kFault, msg.utime, msg);
  check();
}
void LogWritingHandler::on_truth_state(const manip::state_t& msg) {
  w_.write_message(channels::kTruthState, msg.utime, msg);
  check();
}
void LogWritingHandler::on_truth_impedance(const manip::impedance_truth_t& msg) {
  w_.write_message(channels::kTruthImpedance, last_utime_, msg);
  check();
}
void LogWritingHandler::close() {
  if (!w_.close()) throw std::runtime_error(w_.error());
}

namespace {

template <class Msg, class Fn>
bool dispatch(const RawEvent& ev, Msg& msg, LogReadSummary& sum, SessionHandler& h, Fn&& fn) {
  if (!decode(ev, msg)) {
    ++sum.undecodable;
    h.on_warning("byte " + std::to_string(ev.offset) + ": event on " + std::string(ev.channel) +
                 " does not decode as manip type (schema mismatch or corruption); skipped");
    return false;
  }
  fn(msg);
  return true;
}

}  // namespace

LogReadSummary read_log(const std::string& path, SessionHandler& handler) {
  EventLogReader reader(path);
  LogReadSummary sum;
  RawEvent ev;
  manip::session_t session;
  manip::state_t state;
  manip::trial_event_t event;
  manip::fault_t fault;
  manip::impedance_truth_t truth;
  std::size_t reported_skips = 0;
  auto report_skips = [&]() {
    const auto& d = reader.diagnostics();
    for (; reported_skips < d.skipped.size(); ++reported_skips) {
      const auto& s = d.skipped[reported_skips];
      handler.on_warning(path + ": skipped " + std::to_string(s.bytes) + " bytes of garbage at byte " +
                         std::to_string(s.offset) + " (resynchronised on the next event)");
    }
  };
  while (reader.next(ev)) {
    report_skips();
    const std::string_view ch = ev.channel;
    if (ch == channels::kState) {
      dispatch(ev, state, sum, handler, [&](const auto& m) { handler.on_state(m); });
    } else if (ch == channels::kTrial) {
      dispatch(ev, event, sum, handler, [&](const auto& m) { handler.on_trial_event(m); });
    } else if (ch == channels::kSession) {
      // A session_t of another schema version has another fingerprint: peek at
      // the version field (right after the 8-byte fingerprint) to name it.
      if (!decode(ev, session)) {
        if (ev.data.size() >= 12) {
          const auto* p = ev.data.data() + 8;
          const std::int32_t v = static_cast<std::int32_t>((std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) |
                                                           (std::uint32_t(p[2]) << 8) | std::uint32_t(p[3]));
          if (v != manip::session_t::SCHEMA_VERSION && v > 0 && v < 1000)
            throw std::runtime_error(path + ": log written with manip schema version " + std::to_string(v) +
                                     ", this build reads version " +
                                     std::to_string(manip::session_t::SCHEMA_VERSION));
        }
        throw std::runtime_error(path + ": session message at byte " + std::to_string(ev.offset) +
                                 " does not decode (not a manip log of schema version " +
                                 std::to_string(manip::session_t::SCHEMA_VERSION) + ")");
      }
      if (session.schema_version != manip::session_t::SCHEMA_VERSION)
        throw std::runtime_error(path + ": log written with manip schema version " +
                                 std::to_string(session.schema_version) + ", this build reads version " +
                                 std::to_string(manip::session_t::SCHEMA_VERSION));
      handler.on_session(session);
    } else if (ch == channels::kTruthState) {
      dispatch(ev, state, sum, handler, [&](const auto& m) { handler.on_truth_state(m); });
    } else if (ch == channels::kTruthImpedance) {
      dispatch(ev, truth, sum, handler, [&](const auto& m) { handler.on_truth_impedance(m); });
    } else if (ch == channels::kFault) {
      dispatch(ev, fault, sum, handler, [&](const auto& m) { handler.on_fault(m); });
    } else {
      ++sum.unknown_channels;
    }
  }
  report_skips();
  sum.diagnostics = reader.diagnostics();
  if (sum.diagnostics.truncated_tail)
    handler.on_warning(path + ": last event at byte " + std::to_string(sum.diagnostics.truncated_offset) +
                       " is truncated (file cut short); ignored");
  return sum;
}

}  // namespace manip::logging
