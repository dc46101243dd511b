#include "manip/logging/event_log.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace manip::logging {
namespace {

constexpr std::size_t kHeaderBytes = kEventHeaderBytes;
constexpr std::uint64_t kNone = std::numeric_limits<std::uint64_t>::max();

std::uint32_t be32(const std::uint8_t* p) {
  return (std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) | (std::uint32_t(p[2]) << 8) | std::uint32_t(p[3]);
}
std::uint64_t be64(const std::uint8_t* p) { return (std::uint64_t(be32(p)) << 32) | be32(p + 4); }
void put32(std::uint8_t* p, std::uint32_t v) {
  p[0] = std::uint8_t(v >> 24);
  p[1] = std::uint8_t(v >> 16);
  p[2] = std::uint8_t(v >> 8);
  p[3] = std::uint8_t(v);
}
void put64(std::uint8_t* p, std::uint64_t v) {
  put32(p, std::uint32_t(v >> 32));
  put32(p + 4, std::uint32_t(v));
}
bool plausible_lengths(std::int32_t chan_len, std::int32_t data_len) {
  return chan_len > 0 && chan_len <= EventLogReader::kMaxChannelBytes && data_len >= 0 &&
         data_len <= EventLogReader::kMaxDataBytes;
}

}  // namespace

EventLogReader::EventLogReader(const std::string& path) : path_(path) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw std::runtime_error(path + ": cannot open (" + std::strerror(errno) + ")");
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd_);
    fd_ = -1;
    throw std::runtime_error(path + ": not a regular file");
  }
  file_size_ = static_cast<std::uint64_t>(st.st_size);
  std::uint8_t m[4];
  if (file_size_ < 4 || !peek(0, m, 4) || be32(m) != kEventMagic) {
    ::close(fd_);
    fd_ = -1;
    throw std::runtime_error(path + ": not an LCM event log (no event magic at byte 0)");
  }
}

EventLogReader::~EventLogReader() {
  if (fd_ >= 0) ::close(fd_);
}

bool EventLogReader::peek(std::uint64_t off, std::uint8_t* out, std::size_t n) const {
  if (off > file_size_ || n > file_size_ - off) return false;
  if (off >= win_off_ && off + n <= win_off_ + win_len_) {
    std::memcpy(out, buf_.data() + (off - win_off_), n);
    return true;
  }
  std::size_t got = 0;
  while (got < n) {
    const ssize_t r = ::pread(fd_, out + got, n - got, static_cast<off_t>(off + got));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return false;  // I/O error or the file shrank: treated as its end
    got += static_cast<std::size_t>(r);
  }
  return true;
}

const std::uint8_t* EventLogReader::view(std::uint64_t off, std::size_t n) {
  if (off > file_size_ || n > file_size_ - off) return nullptr;
  if (off >= win_off_ && off + n <= win_off_ + win_len_) return buf_.data() + (off - win_off_);
  if (buf_.size() < n || buf_.empty()) {
    // Free the old buffer before allocating the new one, so the peak is the
    // new size only (the bound stated in the header).
    // Never more than the file itself holds.
    buf_ = {};
    buf_.resize(static_cast<std::size_t>(
        std::min<std::uint64_t>(std::max(kMinBufferBytes, n + kReadAheadBytes), std::max<std::uint64_t>(file_size_, n))));
  }
  const std::size_t want = static_cast<std::size_t>(std::min<std::uint64_t>(buf_.size(), file_size_ - off));
  win_off_ = off;
  win_len_ = 0;
  while (win_len_ < want) {
    const ssize_t r = ::pread(fd_, buf_.data() + win_len_, want - win_len_, static_cast<off_t>(off + win_len_));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) break;
    win_len_ += static_cast<std::size_t>(r);
  }
  return win_len_ >= n ? buf_.data() : nullptr;
}

EventLogReader::Frame EventLogReader::parse_header(std::uint64_t off, Header& h) const {
  std::uint8_t p[kHeaderBytes];
  if (!peek(off, p, 4) || be32(p) != kEventMagic) return Frame::no_magic;
  // A magic whose header is cut by the end of the file: a truncated last event
  // (if nothing valid follows, which is trivially true here).
  if (!peek(off, p, kHeaderBytes)) return Frame::beyond_eof;
  const auto chan_len = static_cast<std::int32_t>(be32(p + 20));
  const auto data_len = static_cast<std::int32_t>(be32(p + 24));
  if (!plausible_lengths(chan_len, data_len)) return Frame::bad_header;
  h.event_number = static_cast<std::int64_t>(be64(p + 4));
  h.utime = static_cast<std::int64_t>(be64(p + 12));
  h.total = kHeaderBytes + static_cast<std::uint64_t>(chan_len) + static_cast<std::uint64_t>(data_len);
  // Lengths are bounded by the bytes left, never trusted beyond them.
  if (h.total > file_size_ - off) return Frame::beyond_eof;
  // Channel names are text: control characters mean a misread header.
  std::uint8_t chan[kMaxChannelBytes];
  if (!peek(off + kHeaderBytes, chan, static_cast<std::size_t>(chan_len))) return Frame::beyond_eof;
  for (std::int32_t i = 0; i < chan_len; ++i)
    if (chan[i] < 0x20 || chan[i] == 0x7f) return Frame::bad_header;
  return Frame::ok;
}

bool EventLogReader::followed_by_event(std::uint64_t end) const {
  if (end == file_size_) return true;
  std::uint8_t p[kHeaderBytes];
  if (!peek(end, p, 4) || be32(p) != kEventMagic) return false;
  if (!peek(end, p, kHeaderBytes)) return true;  // a magic with a cut header: the truncated last event
  return plausible_lengths(static_cast<std::int32_t>(be32(p + 20)), static_cast<std::int32_t>(be32(p + 24)));
}

EventLogReader::Scan EventLogReader::scan(std::uint64_t from, std::uint64_t limit) {
  Scan r{limit, kNone};
  limit = std::min(limit, file_size_);
  std::uint64_t off = from;
  while (off < limit && file_size_ - off >= 4) {
    const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(kReadAheadBytes, file_size_ - off));
    const std::uint8_t* p = view(off, n);
    if (!p) break;
    // Candidate magic starts in [off, off + m); the last 3 bytes of the window
    // are rescanned with the next one (a magic can straddle windows).
    const std::size_t m = static_cast<std::size_t>(std::min<std::uint64_t>(n - 3, limit - off));
    std::size_t i = 0;
    while (i < m) {
      const void* hit = std::memchr(p + i, 0xED, m - i);
      if (!hit) break;
      i = static_cast<std::size_t>(static_cast<const std::uint8_t*>(hit) - p);
      if (be32(p + i) == kEventMagic) {
        // parse_header and followed_by_event only peek: p stays valid.
        Header h;
        const Frame f = parse_header(off + i, h);
        if (f == Frame::ok && followed_by_event(off + i + h.total)) {
          r.next = off + i;
          return r;
        }
        if (f == Frame::beyond_eof && r.beyond_eof == kNone) r.beyond_eof = off + i;
      }
      ++i;
    }
    off += m;
  }
  return r;
}

void EventLogReader::skip(std::uint64_t from, std::uint64_t to, std::string why) {
  if (to <= from) return;
  diag_.skipped.push_back({from, to - from, std::move(why)});
  diag_.bytes_skipped += to - from;
}

bool EventLogReader::next(RawEvent& ev) {
  while (pos_ < file_size_) {
    Header h;
    const Frame f = parse_header(pos_, h);
    if (f == Frame::ok) {
      if (!followed_by_event(pos_ + h.total)) {
        // Garbage after this event, or a corrupted length. If a valid event
        // starts inside the declared span, the length is wrong: skip to it.
        // Otherwise the event is whole and the garbage follows it.
        const Scan s = scan(pos_ + 1, pos_ + h.total);
        if (s.next < pos_ + h.total) {
          skip(pos_, s.next,
               "event at byte " + std::to_string(pos_) + " declares " + std::to_string(h.total) +
                   " bytes but no event follows its end, and one starts at byte " + std::to_string(s.next) +
                   " inside it (corrupted length field)");
          pos_ = s.next;
          continue;
        }
      }
      const std::uint8_t* p = view(pos_, static_cast<std::size_t>(h.total));
      if (!p) break;  // read error: the file shrank under us
      const auto chan_len = static_cast<std::size_t>(be32(p + 20));
      ev.offset = pos_;
      ev.event_number = h.event_number;
      ev.utime = h.utime;
      ev.channel = std::string_view(reinterpret_cast<const char*>(p + kHeaderBytes), chan_len);
      ev.data = std::span<const std::uint8_t>(p + kHeaderBytes + chan_len, static_cast<std::size_t>(h.total) - kHeaderBytes - chan_len);
      diag_.largest_event_bytes = std::max(diag_.largest_event_bytes, h.total);
      ++diag_.events;
      pos_ += h.total;
      return true;
    }
    // No acceptable event here: resynchronise on the next valid event.
    const Scan s = scan(pos_ + 1, file_size_);
    if (s.next < file_size_) {
      skip(pos_, s.next,
           f == Frame::beyond_eof
               ? "event at byte " + std::to_string(pos_) + " runs past the end of the file but valid events follow"
               : std::string(f == Frame::no_magic ? "no event magic" : "implausible event header"));
      pos_ = s.next;
      continue;
    }
    // Nothing valid up to the end: a truncated last event if one starts here
    // or inside, garbage otherwise.
    const std::uint64_t cut = f == Frame::beyond_eof ? pos_ : s.beyond_eof;
    if (cut != kNone) {
      skip(pos_, cut, std::string(f == Frame::no_magic ? "no event magic" : "implausible event header"));
      diag_.truncated_tail = true;
      diag_.truncated_offset = cut;
    } else {
      skip(pos_, file_size_, std::string(f == Frame::no_magic ? "no event magic" : "implausible event header"));
    }
    pos_ = file_size_;
  }
  return false;
}

EventLogWriter::~EventLogWriter() { close(); }

bool EventLogWriter::open(const std::string& path) {
  close();
  error_.clear();
  path_ = path;
  f_ = std::fopen(path.c_str(), "wb");
  if (!f_) {
    error_ = path + ": cannot create (" + std::strerror(errno) + ")";
    return false;
  }
  iobuf_.resize(1 << 20);
  std::setvbuf(f_, iobuf_.data(), _IOFBF, iobuf_.size());
  next_event_ = 0;
  return true;
}

bool EventLogWriter::write(std::string_view channel, std::int64_t utime, std::span<const std::uint8_t> data) {
  if (!f_ || !error_.empty()) {
    if (error_.empty()) error_ = "log not open";
    return false;
  }
  std::uint8_t hdr[kHeaderBytes];
  put32(hdr, kEventMagic);
  put64(hdr + 4, static_cast<std::uint64_t>(next_event_));
  put64(hdr + 12, static_cast<std::uint64_t>(utime));
  put32(hdr + 20, static_cast<std::uint32_t>(channel.size()));
  put32(hdr + 24, static_cast<std::uint32_t>(data.size()));
  if (std::fwrite(hdr, 1, sizeof hdr, f_) != sizeof hdr ||
      std::fwrite(channel.data(), 1, channel.size(), f_) != channel.size() ||
      std::fwrite(data.data(), 1, data.size(), f_) != data.size()) {
    error_ = path_ + ": write failed at event " + std::to_string(next_event_) + " (" + std::strerror(errno) + ")";
    return false;
  }
  ++next_event_;
  return true;
}

bool EventLogWriter::flush() {
  if (!f_) return false;
  if (std::fflush(f_) != 0) {
    if (error_.empty()) error_ = path_ + ": flush failed (" + std::strerror(errno) + ")";
    return false;
  }
  return error_.empty();
}

bool EventLogWriter::close() {
  if (!f_) return error_.empty();
  const bool flushed = std::fflush(f_) == 0;
  const bool closed = std::fclose(f_) == 0;
  f_ = nullptr;
  if ((!flushed || !closed) && error_.empty()) error_ = path_ + ": close failed (" + std::strerror(errno) + ")";
  return error_.empty();
}

}  // namespace manip::logging
