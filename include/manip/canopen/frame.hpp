#pragma once
// CAN frames and CANopen COB-IDs (CiA 301 §7.3.3, pre-defined connection set).
// Plain values: no allocation, copyable, usable in the cyclic path.
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>

namespace manip::canopen {

struct CanFrame {
  static constexpr uint8_t kRtr = 0x1;    // remote transmission request
  static constexpr uint8_t kError = 0x2;  // controller error frame (SocketCAN CAN_ERR_FLAG)
  uint32_t id = 0;                        // 11-bit identifier (CAN 2.0A); error class for error frames
  uint8_t dlc = 0;
  uint8_t data[8] = {0, 0, 0, 0, 0, 0, 0, 0};
  uint8_t flags = 0;

  bool is_error() const { return (flags & kError) != 0; }
  bool is_rtr() const { return (flags & kRtr) != 0; }
};

inline bool operator==(const CanFrame& a, const CanFrame& b) {
  return a.id == b.id && a.dlc == b.dlc && a.flags == b.flags &&
         std::memcmp(a.data, b.data, a.dlc) == 0;
}

inline CanFrame make_frame(uint32_t id, std::initializer_list<uint8_t> bytes) {
  CanFrame f;
  f.id = id;
  for (uint8_t b : bytes) {
    if (f.dlc < 8) f.data[f.dlc++] = b;
  }
  return f;
}

// Fixed-capacity frame list: the caller owns it, the cyclic path never allocates.
class FrameBuffer {
 public:
  static constexpr std::size_t kCapacity = 64;
  bool push(const CanFrame& f) {
    if (n_ >= kCapacity) {
      ++overflow_;
      return false;
    }
    frames_[n_++] = f;
    return true;
  }
  void clear() { n_ = 0; }
  std::size_t size() const { return n_; }
  bool empty() const { return n_ == 0; }
  const CanFrame& operator[](std::size_t i) const { return frames_[i]; }
  const CanFrame* begin() const { return frames_.data(); }
  const CanFrame* end() const { return frames_.data() + n_; }
  std::span<const CanFrame> span() const { return {frames_.data(), n_}; }
  std::size_t overflow_count() const { return overflow_; }

 private:
  std::array<CanFrame, kCapacity> frames_{};
  std::size_t n_ = 0;
  std::size_t overflow_ = 0;
};

// Pre-defined connection set, CiA 301 §7.3.3 table 73.
namespace cob {
constexpr uint32_t kNmt = 0x000;
constexpr uint32_t kSync = 0x080;
constexpr uint32_t kEmcyBase = 0x080;
constexpr uint32_t kTpdoBase[4] = {0x180, 0x280, 0x380, 0x480};
constexpr uint32_t kRpdoBase[4] = {0x200, 0x300, 0x400, 0x500};
constexpr uint32_t kSdoTxBase = 0x580;  // server -> client (drive answers)
constexpr uint32_t kSdoRxBase = 0x600;  // client -> server (master requests)
constexpr uint32_t kHeartbeatBase = 0x700;
constexpr uint32_t emcy(uint8_t node) { return kEmcyBase + node; }
constexpr uint32_t tpdo(int n, uint8_t node) { return kTpdoBase[n] + node; }
constexpr uint32_t rpdo(int n, uint8_t node) { return kRpdoBase[n] + node; }
constexpr uint32_t sdo_tx(uint8_t node) { return kSdoTxBase + node; }
constexpr uint32_t sdo_rx(uint8_t node) { return kSdoRxBase + node; }
constexpr uint32_t heartbeat(uint8_t node) { return kHeartbeatBase + node; }
}  // namespace cob

// Function code and node id of a pre-defined-set COB-ID.
inline uint32_t function_code(uint32_t id) { return id & 0x780u; }
inline uint8_t node_of(uint32_t id) { return static_cast<uint8_t>(id & 0x7Fu); }

// NMT command specifiers (CiA 301 §7.2.8.3.1) and heartbeat states (§7.2.8.3.2.3).
enum class NmtCommand : uint8_t { Start = 0x01, Stop = 0x02, EnterPreOperational = 0x80, ResetNode = 0x81, ResetCommunication = 0x82 };
enum class NmtState : uint8_t { BootUp = 0x00, Stopped = 0x04, Operational = 0x05, PreOperational = 0x7F, Unknown = 0xFF };
const char* to_string(NmtState s);

inline CanFrame nmt_frame(NmtCommand c, uint8_t node /*0 = all*/) {
  return make_frame(cob::kNmt, {static_cast<uint8_t>(c), node});
}

// Little-endian helpers (CANopen is little endian, CiA 301 §7.1.2).
inline void put_u16(uint8_t* p, uint16_t v) { p[0] = uint8_t(v); p[1] = uint8_t(v >> 8); }
inline void put_u32(uint8_t* p, uint32_t v) {
  p[0] = uint8_t(v); p[1] = uint8_t(v >> 8); p[2] = uint8_t(v >> 16); p[3] = uint8_t(v >> 24);
}
inline uint16_t get_u16(const uint8_t* p) { return uint16_t(p[0] | (p[1] << 8)); }
inline uint32_t get_u32(const uint8_t* p) {
  return uint32_t(p[0]) | (uint32_t(p[1]) << 8) | (uint32_t(p[2]) << 16) | (uint32_t(p[3]) << 24);
}

// Transport: a SocketCAN socket or a VirtualBus endpoint. Non-blocking both ways.
class CanPort {
 public:
  virtual ~CanPort() = default;
  // false when the frame could not be queued (buffer full, interface down).
  virtual bool send(const CanFrame& f) = 0;
  // Up to out.size() frames received so far (data and error frames); never blocks.
  virtual std::size_t receive(std::span<CanFrame> out) = 0;
};

}  // namespace manip::canopen
