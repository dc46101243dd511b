#pragma once
// Passive SDO client (CiA 301 §7.2.4): expedited and segmented download and
// upload. Fed with frames and the time; returns frames through a FrameBuffer.
// Used only at start-up and shutdown (the Master refuses SDOs in the cyclic
// phase: a confirmed SDO round trip takes milliseconds on a loaded bus).
#include <array>
#include <cstdint>
#include <span>

#include "manip/canopen/error.hpp"
#include "manip/canopen/frame.hpp"

namespace manip::canopen {

// Command specifiers (CiA 301 §7.2.4.3), byte 0 of the SDO frame.
namespace sdo {
constexpr uint8_t kAbort = 0x80;
uint8_t expedited_download_cs(int bytes);  // 0x2F/0x2B/0x27/0x23 for 1..4 bytes
CanFrame expedited_download(uint8_t node, uint16_t index, uint8_t sub, uint32_t value, int bytes);
CanFrame upload_request(uint8_t node, uint16_t index, uint8_t sub);
CanFrame abort_frame(uint32_t cob_id, uint16_t index, uint8_t sub, uint32_t code);
}  // namespace sdo

class SdoClient {
 public:
  enum class Status : uint8_t { Idle, Busy, Done, Failed };
  static constexpr std::size_t kMaxData = 256;

  void set_node(uint8_t node) { node_ = node; }
  uint8_t node() const { return node_; }
  void set_timeout_us(int64_t t) { timeout_us_ = t; }

  // Start a transfer; data longer than 4 bytes goes segmented.
  void download(int64_t now, uint16_t index, uint8_t sub, std::span<const uint8_t> data, FrameBuffer& tx);
  void download_u32(int64_t now, uint16_t index, uint8_t sub, uint32_t value, int bytes, FrameBuffer& tx);
  void upload(int64_t now, uint16_t index, uint8_t sub, FrameBuffer& tx);

  // A frame with COB-ID 0x580+node. Returns false if it is not for this client.
  bool on_frame(int64_t now, const CanFrame& f, FrameBuffer& tx);
  // Timeout check: aborts the transfer (abort 0x05040000 sent to the server).
  void poll(int64_t now, FrameBuffer& tx);

  Status status() const { return status_; }
  bool busy() const { return status_ == Status::Busy; }
  const Error& error() const { return error_; }
  std::span<const uint8_t> data() const { return {data_.data(), size_}; }
  uint32_t value_u32() const;  // little-endian value of an upload (<= 4 bytes)
  void reset() { status_ = Status::Idle; }

 private:
  enum class Op : uint8_t { None, DownloadInit, DownloadSegment, UploadInit, UploadSegment };
  void fail(ErrorCode c, uint32_t value, int64_t now, FrameBuffer* tx, uint32_t abort_to_send);
  void send_segment(FrameBuffer& tx);

  uint8_t node_ = 0;
  int64_t timeout_us_ = 100000;
  Status status_ = Status::Idle;
  Op op_ = Op::None;
  uint16_t index_ = 0;
  uint8_t sub_ = 0;
  bool toggle_ = false;
  int64_t deadline_us_ = 0;
  std::array<uint8_t, kMaxData> data_{};
  std::size_t size_ = 0;     // bytes held (upload) / total (download)
  std::size_t offset_ = 0;   // bytes sent (download)
  Error error_{};
};

}  // namespace manip::canopen
