#include "manip/logging/event_log.hpp"

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace manip::logging {
namespace {

constexpr std::size_t kHeaderBytes = 4 + 8 + 8 + 4 + 4;
// LCM channel names are short; payloads beyond this are treated as corruption
// (a real manip log never has an event near that size).
constexpr std::int32_t kMaxChannel = 1024;
constexpr std::int64_t kMaxData = 256LL << 20;
constexpr std::size_t kChunk = 1 << 20;

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

}  // namespace

EventLogReader::EventLogReader(const std::string& path) : path_(path) {
  f_ = std::fopen(path.c_str(), "rb");
  if (!f_) throw std::runtime_error(path + ": cannot open (" + std::strerror(errno) + ")");
  if (std::fseek(f_, 0, SEEK_END) == 0) {
    const long sz = std::ftell(f_);
    file_size_ = sz > 0 ? static_cast<std::uint64_t>(sz) : 0;
    std::fseek(f_, 0, SEEK_SET);
  }
  buf_.resize(2 * kChunk);
  if (!fill(4) || be32(buf_.data() + begin_) != kEventMagic) {
    std::fclose(f_);
    f_ = nullptr;
    throw std::runtime_error(path + ": not an LCM event log (no event magic at byte 0)");
  }
}

EventLogReader::~EventLogReader() {
  if (f_) std::fclose(f_);
}

bool EventLogReader::fill(std::size_t need) {
  while (end_ - begin_ < need) {
    if (eof_) return false;
    if (begin_ > 0) {  // compact
      std::memmove(buf_.data(), buf_.data() + begin_, end_ - begin_);
      buf_offset_ += begin_;
      end_ -= begin_;
      begin_ = 0;
    }
    if (buf_.size() - end_ < kChunk || buf_.size() < need) buf_.resize(std::max(buf_.size() * 2, need + kChunk));
    const std::size_t got = std::fread(buf_.data() + end_, 1, buf_.size() - end_, f_);
    if (got == 0) eof_ = true;
    end_ += got;
  }
  return true;
}

bool EventLogReader::next(RawEvent& ev) {
  std::uint64_t skip_start = 0;
  bool skipping = false;
  auto end_skip = [&](std::uint64_t at) {
    if (skipping) {
      diag_.skipped.push_back({skip_start, at - skip_start});
      diag_.bytes_skipped += at - skip_start;
      skipping = false;
    }
  };
  for (;;) {
    if (!fill(kHeaderBytes)) {
      const std::uint64_t here = buf_offset_ + begin_;
      if (end_ > begin_) {  // a few trailing bytes: either garbage or a cut header
        if (!skipping && end_ - begin_ >= 4 && be32(buf_.data() + begin_) == kEventMagic) {
          diag_.truncated_tail = true;
          diag_.truncated_offset = here;
        } else {
          if (!skipping) {
            skip_start = here;
            skipping = true;
          }
        }
        begin_ = end_;
      }
      end_skip(buf_offset_ + end_);
      return false;
    }
    const std::uint8_t* p = buf_.data() + begin_;
    const std::uint64_t here = buf_offset_ + begin_;
    if (be32(p) != kEventMagic) {
      if (!skipping) {
        skip_start = here;
        skipping = true;
      }
      ++begin_;
      continue;
    }
    const auto chan_len = static_cast<std::int32_t>(be32(p + 20));
    const auto data_len = static_cast<std::int32_t>(be32(p + 24));
    if (chan_len <= 0 || chan_len > kMaxChannel || data_len < 0 || data_len > kMaxData) {
      // A magic inside garbage or a corrupted header: keep scanning.
      if (!skipping) {
        skip_start = here;
        skipping = true;
      }
      ++begin_;
      continue;
    }
    const std::size_t total = kHeaderBytes + std::size_t(chan_len) + std::size_t(data_len);
    if (!fill(total)) {
      // Not enough bytes left: the last event was cut short.
      end_skip(here);
      diag_.truncated_tail = true;
      diag_.truncated_offset = here;
      begin_ = end_;
      return false;
    }
    p = buf_.data() + begin_;
    // A garbage region may contain a spurious magic with plausible lengths; an
    // event is accepted only if the next bytes are another magic or the end.
    if (skipping) {
      const bool at_end = !fill(total + 4);
      p = buf_.data() + begin_;
      if (!at_end && be32(p + total) != kEventMagic) {
        ++begin_;
        continue;
      }
    }
    end_skip(here);
    ev.offset = here;
    ev.event_number = static_cast<std::int64_t>(be64(p + 4));
    ev.utime = static_cast<std::int64_t>(be64(p + 12));
    ev.channel = std::string_view(reinterpret_cast<const char*>(p + kHeaderBytes), std::size_t(chan_len));
    ev.data = std::span<const std::uint8_t>(p + kHeaderBytes + chan_len, std::size_t(data_len));
    begin_ += total;
    ++diag_.events;
    return true;
  }
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
