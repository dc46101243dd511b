#pragma once
// LCM event-log files (the format of lcm-logger and lcm::LogFile), read and
// written without going through lcm::LogFile:
//  - the reader streams (bounded memory however long the log) and never
//    trusts a length field: an event is accepted only if its declared end is
//    followed by another event (or is the end of the file); anything else is
//    resynchronised over byte by byte and reported (offset, bytes, why);
//  - the writer reports errors (e.g. a full disk) as values, never silently.
// Event layout (big endian): u32 magic 0xEDA1DA01, i64 event number,
// i64 timestamp [us], i32 channel length, i32 data length, channel, data.
// The framing rules are written down in docs/schema.md ("Reading damaged logs").
#include <cstdint>
#include <cstdio>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "manip/logging/safe_decode.hpp"

namespace manip::logging {

inline constexpr std::uint32_t kEventMagic = 0xEDA1DA01u;
inline constexpr std::size_t kEventHeaderBytes = 4 + 8 + 8 + 4 + 4;

struct RawEvent {
  std::int64_t event_number{};
  std::int64_t utime{};
  std::string_view channel;          // valid until the next call to next()
  std::span<const std::uint8_t> data;  // valid until the next call to next()
  std::uint64_t offset{};            // byte offset of the event's magic in the file
};

struct SkippedRegion {
  std::uint64_t offset{};  // first byte skipped
  std::uint64_t bytes{};
  std::string why;         // e.g. "no event magic", "event at byte N declares ... (corrupted length)"
};

struct ReadDiagnostics {
  std::vector<SkippedRegion> skipped;  // regions resynchronised over, in file order
  std::uint64_t bytes_skipped{};
  bool truncated_tail{false};          // last event cut short (reported, not decoded)
  std::uint64_t truncated_offset{};
  std::uint64_t events{};
  std::uint64_t largest_event_bytes{};  // header + channel + data of the largest accepted event
};

// Reads a log file as it is when opened (its size is taken at open).
//
// Framing (what is accepted as an event at offset p):
//  - magic at p, channel length 1..kMaxChannelBytes of bytes without control
//    characters, data length 0..kMaxDataBytes, and the whole event inside the
//    file (lengths are bounded by the bytes left, never trusted beyond them);
//  - its end is the end of the file or another magic with plausible lengths;
//  - exception, so that garbage *after* a good event does not cost that
//    event: an event starting where the previous one ended (or at byte 0)
//    whose end is followed by garbage is still accepted if no valid event
//    starts inside its declared span (otherwise its length is corrupt: it is
//    skipped and reading resumes at that inner event).
// Everything else is skipped up to the next offset that passes these rules
// and reported in diagnostics().skipped. A "truncated last event" is reported
// only when no valid event follows it anywhere in the file.
//
// Allocation bound: the read buffer is the only allocation that grows with
// the input. It holds min(file size, max(kMinBufferBytes, E + kReadAheadBytes))
// bytes, where E is the size of the largest event accepted so far
// (E <= kEventHeaderBytes + kMaxChannelBytes + kMaxDataBytes, and E <= the
// file size); the old buffer is freed before a larger one is allocated. A declared
// length is never allocated before the event passed the framing checks,
// which read only the 28-byte header, the channel and the next header.
// buffer_bytes() reports the buffer's size (it never shrinks, so it is the
// peak).
class EventLogReader {
 public:
  static constexpr std::int32_t kMaxChannelBytes = 1024;
  static constexpr std::int64_t kMaxDataBytes = std::int64_t{256} << 20;
  static constexpr std::size_t kReadAheadBytes = std::size_t{1} << 20;
  static constexpr std::size_t kMinBufferBytes = std::size_t{2} << 20;

  // Throws std::runtime_error("<path>: ...") if the file cannot be opened, is
  // not a regular file, or does not start with an LCM event (not an LCM log).
  explicit EventLogReader(const std::string& path);
  ~EventLogReader();
  EventLogReader(const EventLogReader&) = delete;
  EventLogReader& operator=(const EventLogReader&) = delete;

  // Next good event; false at the end of the file.
  bool next(RawEvent& ev);
  [[nodiscard]] const ReadDiagnostics& diagnostics() const { return diag_; }
  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] std::uint64_t file_size() const { return file_size_; }
  [[nodiscard]] std::size_t buffer_bytes() const { return buf_.size(); }

 private:
  enum class Frame { ok, no_magic, bad_header, beyond_eof };
  struct Header {
    std::int64_t event_number{}, utime{};
    std::uint64_t total{};  // header + channel + data
  };
  struct Scan {
    std::uint64_t next;         // first valid event at or after `from`, or `limit` if none
    std::uint64_t beyond_eof;   // first magic with plausible lengths that runs past the end, or UINT64_MAX
  };
  Frame parse_header(std::uint64_t off, Header& h) const;
  [[nodiscard]] bool followed_by_event(std::uint64_t end) const;
  Scan scan(std::uint64_t from, std::uint64_t limit);
  void skip(std::uint64_t from, std::uint64_t to, std::string why);
  bool peek(std::uint64_t off, std::uint8_t* out, std::size_t n) const;  // copy without moving the window
  const std::uint8_t* view(std::uint64_t off, std::size_t n);            // window over [off, off + n)

  std::string path_;
  int fd_{-1};
  std::uint64_t file_size_{0};
  std::uint64_t pos_{0};  // next byte to examine
  std::vector<std::uint8_t> buf_;
  std::uint64_t win_off_{0};  // file offset of buf_[0]
  std::size_t win_len_{0};    // valid bytes in buf_
  ReadDiagnostics diag_;
};

class EventLogWriter {
 public:
  EventLogWriter() = default;
  ~EventLogWriter();
  EventLogWriter(const EventLogWriter&) = delete;
  EventLogWriter& operator=(const EventLogWriter&) = delete;

  // False (and error() says why) if the file cannot be created.
  bool open(const std::string& path);
  // False once any write failed (disk full, I/O error); error() names it. The
  // event counter only advances for events handed to the OS buffer.
  bool write(std::string_view channel, std::int64_t utime, std::span<const std::uint8_t> data);
  bool flush();
  bool close();
  [[nodiscard]] bool ok() const { return error_.empty(); }
  [[nodiscard]] const std::string& error() const { return error_; }
  [[nodiscard]] std::int64_t events_written() const { return next_event_; }

  // Encode any lcm-gen type into a reused buffer and write it.
  template <class Msg>
  bool write_message(std::string_view channel, std::int64_t utime, const Msg& msg) {
    const int n = msg.getEncodedSize();
    if (scratch_.size() < static_cast<std::size_t>(n)) scratch_.resize(static_cast<std::size_t>(n));
    if (msg.encode(scratch_.data(), 0, n) != n) {
      error_ = "cannot encode message for channel " + std::string(channel);
      return false;
    }
    return write(channel, utime, std::span<const std::uint8_t>(scratch_.data(), static_cast<std::size_t>(n)));
  }

 private:
  std::string path_;
  std::FILE* f_{nullptr};
  std::int64_t next_event_{0};
  std::string error_;
  std::vector<std::uint8_t> scratch_;
  std::vector<char> iobuf_;
};

// Decode a manip message from an event through safe_decode (never throws,
// never trusts a length field); false if the payload does not decode as Msg.
template <class Msg>
bool decode(const RawEvent& ev, Msg& out) {
  return safe_decode(ev.data, out).ok();
}

}  // namespace manip::logging
