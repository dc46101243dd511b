#include "manip/logging/safe_decode.hpp"

#include <exception>
#include <limits>

#include "manip/command_status_t.hpp"
#include "manip/command_t.hpp"
#include "manip/fault_t.hpp"
#include "manip/health_t.hpp"
#include "manip/impedance_truth_t.hpp"
#include "manip/session_t.hpp"
#include "manip/state_t.hpp"
#include "manip/trial_event_t.hpp"

namespace manip::logging {
namespace {

// Walks an LCM encoding field by field without decoding it. Every length is
// checked against the bytes left before it is used.
class Walker {
 public:
  explicit Walker(std::span<const std::uint8_t> d) : d_(d) {}

  bool fixed(std::size_t n) {
    if (left() < n) return fail(DecodeStatus::short_data, static_cast<std::int64_t>(n));
    pos_ += n;
    return true;
  }
  // LCM string: i32 length including the terminating NUL, then the bytes.
  bool string() {
    std::int32_t n = 0;
    if (!i32(n)) return false;
    if (n < 1 || static_cast<std::uint64_t>(n) > left()) {
      pos_ -= 4;  // report the length field itself
      return fail(DecodeStatus::bad_string_length, n);
    }
    pos_ += static_cast<std::size_t>(n);
    return true;
  }
  // Array count stored in the message: >= 0 and at most what the bytes left
  // can hold at `min_element_bytes` each (checked before anything is sized).
  bool count(std::int32_t& n, std::size_t min_element_bytes) {
    if (!i32(n)) return false;
    if (n < 0 || static_cast<std::uint64_t>(n) * min_element_bytes > left()) {
      pos_ -= 4;
      return fail(DecodeStatus::bad_array_length, n);
    }
    return true;
  }
  bool fingerprint(std::uint64_t expected) {
    if (left() < 8) return fail(DecodeStatus::short_data, 8);
    std::uint64_t v = 0;
    for (int i = 0; i < 8; ++i) v = (v << 8) | d_[pos_ + static_cast<std::size_t>(i)];
    if (v != expected) return fail(DecodeStatus::wrong_type, 0);
    pos_ += 8;
    return true;
  }
  DecodeResult finish() {
    if (r_.ok() && pos_ != d_.size()) {
      r_ = {DecodeStatus::size_mismatch, pos_, static_cast<std::int64_t>(d_.size() - pos_)};
    }
    return r_;
  }
  [[nodiscard]] const DecodeResult& result() const { return r_; }

 private:
  [[nodiscard]] std::size_t left() const { return d_.size() - pos_; }
  bool i32(std::int32_t& v) {
    if (left() < 4) return fail(DecodeStatus::short_data, 4);
    const std::uint8_t* p = d_.data() + pos_;
    v = static_cast<std::int32_t>((std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) |
                                  (std::uint32_t(p[2]) << 8) | std::uint32_t(p[3]));
    pos_ += 4;
    return true;
  }
  bool fail(DecodeStatus s, std::int64_t value) {
    r_ = {s, pos_, value};
    return false;
  }
  std::span<const std::uint8_t> d_;
  std::size_t pos_{0};
  DecodeResult r_;
};

// Wire layout of each type: its fingerprint (as lcm-gen computes it for this
// schema) and its fields in order (lcmtypes/*.lcm). Fixed-size runs of
// scalars are summed: i64/double 8, i32 4, i8/boolean 1 byte.
template <class Msg>
struct Layout;

constexpr std::size_t kStateBody = 8 + 8 + 4 + 1 + 8 * 16 + 1 + 4;  // state_t without fingerprint

template <>
struct Layout<manip::state_t> {
  static constexpr std::uint64_t kFingerprint = 0x5451249b6bdc3013ull;
  static bool walk(Walker& w) { return w.fixed(kStateBody); }
};
template <>
struct Layout<manip::trial_event_t> {
  static constexpr std::uint64_t kFingerprint = 0x23dab84d9ec8ea5dull;
  // utime, cycle, trial, kind, perturbed, start[2], goal[2], angle, amplitude, duration; reason
  static bool walk(Walker& w) { return w.fixed(8 + 8 + 4 + 1 + 1 + 16 + 16 + 8 + 8 + 8) && w.string(); }
};
template <>
struct Layout<manip::session_t> {
  static constexpr std::uint64_t kFingerprint = 0x5e374f75a71ee991ull;
  // schema_version; software_version; source; utime_start; participant_id;
  // session_id; 24 doubles (rates, admittance, handle, frame, anthropometrics,
  // body, perturbation design); config_yaml
  static bool walk(Walker& w) {
    return w.fixed(4) && w.string() && w.string() && w.fixed(8) && w.string() && w.string() && w.fixed(24 * 8) &&
           w.string();
  }
};
template <>
struct Layout<manip::fault_t> {
  static constexpr std::uint64_t kFingerprint = 0x02d27d8d481f87fdull;
  // utime, cycle, fault_flags; reason; n_history; history[n_history] (state_t bodies)
  static bool walk(Walker& w) {
    std::int32_t n = 0;
    if (!(w.fixed(8 + 8 + 4) && w.string() && w.count(n, kStateBody))) return false;
    return w.fixed(static_cast<std::size_t>(n) * kStateBody);
  }
};
template <>
struct Layout<manip::health_t> {
  static constexpr std::uint64_t kFingerprint = 0xc85ac0439b9e3647ull;
  // utime, cycle, mode, fault_flags, 5 doubles, 4 int64
  static bool walk(Walker& w) { return w.fixed(8 + 8 + 1 + 4 + 5 * 8 + 4 * 8); }
};
template <>
struct Layout<manip::impedance_truth_t> {
  static constexpr std::uint64_t kFingerprint = 0xfa4dcb953057b016ull;
  // trial, t_est_s, m[4], d[4], k[4]; model
  static bool walk(Walker& w) { return w.fixed(4 + 8 + 3 * 32) && w.string(); }
};
template <>
struct Layout<manip::command_t> {
  static constexpr std::uint64_t kFingerprint = 0x29c7948ec611e4dfull;
  // utime, seq; sender; kind, start[2], goal[2]
  static bool walk(Walker& w) { return w.fixed(8 + 8) && w.string() && w.fixed(1 + 16 + 16); }
};
template <>
struct Layout<manip::command_status_t> {
  static constexpr std::uint64_t kFingerprint = 0x6d7b39ee794e20baull;
  // utime, seq, kind, accepted; reason; mode
  static bool walk(Walker& w) { return w.fixed(8 + 8 + 1 + 1) && w.string() && w.fixed(1); }
};

}  // namespace

std::string DecodeResult::message() const {
  const std::string at_s = " at payload byte " + std::to_string(at);
  switch (status) {
    case DecodeStatus::ok: return "ok";
    case DecodeStatus::short_data: return "payload ends inside a field" + at_s;
    case DecodeStatus::wrong_type: return "fingerprint does not match the type (other type or schema version)";
    case DecodeStatus::bad_string_length:
      return "string length " + std::to_string(value) + at_s + " (must be at least 1, the terminating NUL, and fit the payload)";
    case DecodeStatus::bad_array_length:
      return "array count " + std::to_string(value) + at_s + " (negative or more elements than the payload holds)";
    case DecodeStatus::size_mismatch: return std::to_string(value) + " bytes left over after the message" + at_s;
    case DecodeStatus::decoder_threw: return "the generated decoder threw" + at_s;
    case DecodeStatus::layout_outdated:
      return "this build's wire layout of the type is outdated (schema changed; update src/logging/safe_decode.cpp)";
  }
  return "unknown decode status";
}

template <class Msg>
DecodeResult check_wire_layout(std::span<const std::uint8_t> data) noexcept {
  if (static_cast<std::uint64_t>(Msg::getHash()) != Layout<Msg>::kFingerprint) return {DecodeStatus::layout_outdated, 0, 0};
  if (data.size() > static_cast<std::size_t>(std::numeric_limits<int>::max())) return {DecodeStatus::size_mismatch, 0, 0};
  Walker w(data);
  if (!w.fingerprint(Layout<Msg>::kFingerprint) || !Layout<Msg>::walk(w)) return w.result();
  return w.finish();
}

template <class Msg>
DecodeResult safe_decode(std::span<const std::uint8_t> data, Msg& out) noexcept {
  const DecodeResult r = check_wire_layout<Msg>(data);
  if (!r.ok()) return r;
  const int n = static_cast<int>(data.size());
  try {
    if (out.decode(data.data(), 0, n) != n) return {DecodeStatus::size_mismatch, 0, 0};
  } catch (...) {
    return {DecodeStatus::decoder_threw, 0, 0};
  }
  return {};
}

#define MANIP_SAFE_DECODE_INSTANTIATE(T)                                                     \
  template DecodeResult safe_decode<T>(std::span<const std::uint8_t>, T&) noexcept; \
  template DecodeResult check_wire_layout<T>(std::span<const std::uint8_t>) noexcept;
MANIP_SAFE_DECODE_INSTANTIATE(manip::session_t)
MANIP_SAFE_DECODE_INSTANTIATE(manip::state_t)
MANIP_SAFE_DECODE_INSTANTIATE(manip::trial_event_t)
MANIP_SAFE_DECODE_INSTANTIATE(manip::fault_t)
MANIP_SAFE_DECODE_INSTANTIATE(manip::health_t)
MANIP_SAFE_DECODE_INSTANTIATE(manip::impedance_truth_t)
MANIP_SAFE_DECODE_INSTANTIATE(manip::command_t)
MANIP_SAFE_DECODE_INSTANTIATE(manip::command_status_t)
#undef MANIP_SAFE_DECODE_INSTANTIATE

}  // namespace manip::logging
