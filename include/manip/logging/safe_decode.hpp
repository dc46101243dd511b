#pragma once
// safe_decode: the one way to decode manip LCM messages from untrusted bytes
// (log files, the live bus, the command receiver).
//
// Why: lcm-gen's generated C++ decode checks that a string length is not too
// large but not that it is >= 1 (0 and negative lengths throw
// std::length_error, INT32_MIN overflows), and sizes arrays from the message
// before checking there are bytes for them (fault_t.n_history = 2^31 asks for
// ~350 GB). safe_decode first walks the wire layout of the type (fingerprint,
// every string length in 1..bytes left, every array count in 0..what the
// bytes left can hold, exact total size), and only then runs the generated
// decode (inside a catch-all, as a second line of defence). It never throws
// and allocates at most what the payload itself holds.
//
// Provided for every type in lcmtypes/: session_t, state_t, trial_event_t,
// fault_t, health_t, impedance_truth_t, command_t, command_status_t. The wire
// layouts live in src/logging/safe_decode.cpp next to each type's fingerprint;
// a schema change changes the fingerprint, which makes safe_decode refuse the
// type (DecodeStatus::layout_outdated) until the layout is updated, and the
// logging tests fail at once.
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

namespace manip {
class session_t;
class state_t;
class trial_event_t;
class fault_t;
class health_t;
class impedance_truth_t;
class command_t;
class command_status_t;
}  // namespace manip

namespace manip::logging {

enum class DecodeStatus : std::uint8_t {
  ok,
  short_data,         // payload ends inside a field
  wrong_type,         // fingerprint is not the type's (other type or schema version)
  bad_string_length,  // string length field < 1 or beyond the payload
  bad_array_length,   // array count < 0 or more elements than the bytes left can hold
  size_mismatch,      // bytes left over after the message, or the generated decode disagreed
  decoder_threw,      // the generated decode threw (should not happen after the walk)
  layout_outdated,    // this build's wire layout does not match the generated type (schema changed)
};

struct DecodeResult {
  DecodeStatus status{DecodeStatus::ok};
  std::size_t at{0};       // byte offset in the payload where the problem was found
  std::int64_t value{0};   // the offending length/count, when there is one
  [[nodiscard]] bool ok() const noexcept { return status == DecodeStatus::ok; }
  explicit operator bool() const noexcept { return ok(); }
  // One line, e.g. "string length 0 at payload byte 86 (must be 1..120)".
  [[nodiscard]] std::string message() const;
};

// Decodes `data` (exactly one message, nothing after it) into `out`. On
// failure `out` is unspecified (partially assigned) and the result says why.
template <class Msg>
DecodeResult safe_decode(std::span<const std::uint8_t> data, Msg& out) noexcept;

template <class Msg>
DecodeResult safe_decode(const void* data, std::size_t size, Msg& out) noexcept {
  return safe_decode(std::span<const std::uint8_t>(static_cast<const std::uint8_t*>(data), size), out);
}

// Only the wire walk (no decode): what safe_decode checks before decoding.
template <class Msg>
DecodeResult check_wire_layout(std::span<const std::uint8_t> data) noexcept;

#define MANIP_SAFE_DECODE_EXTERN(T)                                                        \
  extern template DecodeResult safe_decode<T>(std::span<const std::uint8_t>, T&) noexcept; \
  extern template DecodeResult check_wire_layout<T>(std::span<const std::uint8_t>) noexcept;
MANIP_SAFE_DECODE_EXTERN(manip::session_t)
MANIP_SAFE_DECODE_EXTERN(manip::state_t)
MANIP_SAFE_DECODE_EXTERN(manip::trial_event_t)
MANIP_SAFE_DECODE_EXTERN(manip::fault_t)
MANIP_SAFE_DECODE_EXTERN(manip::health_t)
MANIP_SAFE_DECODE_EXTERN(manip::impedance_truth_t)
MANIP_SAFE_DECODE_EXTERN(manip::command_t)
MANIP_SAFE_DECODE_EXTERN(manip::command_status_t)
#undef MANIP_SAFE_DECODE_EXTERN

}  // namespace manip::logging
