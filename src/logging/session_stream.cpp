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

const char* type_name(const manip::state_t*) { return "manip.state_t"; }
const char* type_name(const manip::trial_event_t*) { return "manip.trial_event_t"; }
const char* type_name(const manip::fault_t*) { return "manip.fault_t"; }
const char* type_name(const manip::impedance_truth_t*) { return "manip.impedance_truth_t"; }

std::string where(const std::string& path, const RawEvent& ev) {
  return path + ": byte " + std::to_string(ev.offset) + " (" + std::string(ev.channel) + ")";
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
  bool session_seen = false;
  std::string bad_session;  // why an undecodable session message was skipped, for later errors
  std::size_t reported_skips = 0;
  auto report_skips = [&]() {
    const auto& d = reader.diagnostics();
    for (; reported_skips < d.skipped.size(); ++reported_skips) {
      const auto& s = d.skipped[reported_skips];
      handler.on_warning(path + ": skipped " + std::to_string(s.bytes) + " bytes at byte " + std::to_string(s.offset) +
                         " (" + s.why + "); resynchronised on the next event at byte " +
                         std::to_string(s.offset + s.bytes));
    }
  };
  // Every payload is untrusted: decoded with safe_decode, a bad one is a
  // warning naming file, offset, channel and field, and reading continues.
  auto decoded = [&](auto& msg) {
    const DecodeResult r = safe_decode(ev.data, msg);
    if (r.ok()) return true;
    ++sum.undecodable;
    handler.on_warning(where(path, ev) + ": event does not decode as " + type_name(&msg) + " (" + r.message() +
                       "); skipped");
    return false;
  };
  // Handlers (e.g. the trial assembler) throw std::runtime_error on input they
  // cannot use at all; say where in which file that happened. Other
  // exceptions are bugs, not bad input, and pass through unchanged.
  auto call = [&](auto&& fn) {
    try {
      fn();
    } catch (const std::runtime_error& e) {
      const std::string what = e.what();
      if (what.rfind(path, 0) == 0) throw;  // already names the file
      std::string msg = where(path, ev) + ": " + what;
      if (!bad_session.empty()) msg += " (" + bad_session + ")";
      throw std::runtime_error(msg);
    }
  };
  while (reader.next(ev)) {
    report_skips();
    const std::string_view ch = ev.channel;
    if (ch == channels::kState) {
      if (decoded(state)) call([&] { handler.on_state(state); });
    } else if (ch == channels::kTrial) {
      if (decoded(event)) call([&] { handler.on_trial_event(event); });
    } else if (ch == channels::kSession) {
      const DecodeResult r = safe_decode(ev.data, session);
      if (r.status == DecodeStatus::wrong_type) {
        // A session_t of another schema version has another fingerprint: peek
        // at the version field (right after the 8-byte fingerprint) to name it.
        if (ev.data.size() >= 12) {
          const auto* p = ev.data.data() + 8;
          const std::int32_t v = static_cast<std::int32_t>((std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) |
                                                           (std::uint32_t(p[2]) << 8) | std::uint32_t(p[3]));
          if (v != manip::session_t::SCHEMA_VERSION && v > 0 && v < 1000)
            throw std::runtime_error(path + ": log written with manip schema version " + std::to_string(v) +
                                     ", this build reads version " +
                                     std::to_string(manip::session_t::SCHEMA_VERSION));
        }
        throw std::runtime_error(where(path, ev) + ": session message does not decode (not a manip log of schema version " +
                                 std::to_string(manip::session_t::SCHEMA_VERSION) + ")");
      }
      if (!r.ok()) {
        // Damaged, not foreign: report it and read on (the handler decides
        // whether a log without a usable session message is of any use).
        ++sum.undecodable;
        bad_session = "the session message at byte " + std::to_string(ev.offset) + " was damaged: " + r.message();
        handler.on_warning(where(path, ev) + ": session message does not decode (" + r.message() + "); skipped");
        continue;
      }
      if (session.schema_version != manip::session_t::SCHEMA_VERSION)
        throw std::runtime_error(path + ": log written with manip schema version " +
                                 std::to_string(session.schema_version) + ", this build reads version " +
                                 std::to_string(manip::session_t::SCHEMA_VERSION));
      session_seen = true;
      call([&] { handler.on_session(session); });
    } else if (ch == channels::kTruthState) {
      if (decoded(state)) call([&] { handler.on_truth_state(state); });
    } else if (ch == channels::kTruthImpedance) {
      if (decoded(truth)) call([&] { handler.on_truth_impedance(truth); });
    } else if (ch == channels::kFault) {
      if (decoded(fault)) call([&] { handler.on_fault(fault); });
    } else {
      ++sum.unknown_channels;
    }
  }
  report_skips();
  sum.diagnostics = reader.diagnostics();
  sum.session_seen = session_seen;
  if (sum.diagnostics.truncated_tail)
    handler.on_warning(path + ": last event at byte " + std::to_string(sum.diagnostics.truncated_offset) +
                       " is truncated (file cut short); ignored");
  return sum;
}

}  // namespace manip::logging
