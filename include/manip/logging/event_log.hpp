#pragma once
// LCM event-log files (the format of lcm-logger and lcm::LogFile), read and
// written without going through lcm::LogFile:
//  - the reader streams (bounded memory however long the log), and, unlike the
//    stock reader, survives garbage in the middle (resynchronises on the next
//    event magic and reports the bytes skipped) and a truncated last event;
//  - the writer reports errors (e.g. a full disk) as values, never silently.
// Event layout (big endian): u32 magic 0xEDA1DA01, i64 event number,
// i64 timestamp [us], i32 channel length, i32 data length, channel, data.
#include <cstdint>
#include <cstdio>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace manip::logging {

inline constexpr std::uint32_t kEventMagic = 0xEDA1DA01u;

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
};

struct ReadDiagnostics {
  std::vector<SkippedRegion> skipped;  // garbage regions resynchronised over
  std::uint64_t bytes_skipped{};
  bool truncated_tail{false};          // last event cut short (reported, not decoded)
  std::uint64_t truncated_offset{};
  std::uint64_t events{};
};

class EventLogReader {
 public:
  // Throws std::runtime_error("<path>: ...") if the file cannot be opened or
  // does not start with an LCM event (not an LCM log).
  explicit EventLogReader(const std::string& path);
  ~EventLogReader();
  EventLogReader(const EventLogReader&) = delete;
  EventLogReader& operator=(const EventLogReader&) = delete;

  // Next good event; false at the end of the file.
  bool next(RawEvent& ev);
  [[nodiscard]] const ReadDiagnostics& diagnostics() const { return diag_; }
  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] std::uint64_t file_size() const { return file_size_; }

 private:
  bool fill(std::size_t need);  // ensure `need` bytes from pos_ are buffered
  std::string path_;
  std::FILE* f_{nullptr};
  std::vector<std::uint8_t> buf_;
  std::size_t begin_{0}, end_{0};  // valid bytes buf_[begin_, end_)
  std::uint64_t buf_offset_{0};    // file offset of buf_[0]
  std::uint64_t file_size_{0};
  bool eof_{false};
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

// Decode an lcm-gen message from an event; false if the payload does not
// decode as Msg (wrong fingerprint or short data).
template <class Msg>
bool decode(const RawEvent& ev, Msg& out) {
  return out.decode(ev.data.data(), 0, static_cast<int>(ev.data.size())) == static_cast<int>(ev.data.size());
}

}  // namespace manip::logging
