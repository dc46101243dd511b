#include "manip/canopen/sdo.hpp"

#include <algorithm>

namespace manip::canopen {

namespace sdo {
uint8_t expedited_download_cs(int bytes) {
  // ccs = 1 (bits 7-5 = 001), n = 4 - bytes (bits 3-2), e = 1, s = 1.
  return static_cast<uint8_t>(0x20 | ((4 - bytes) << 2) | 0x03);
}
CanFrame expedited_download(uint8_t node, uint16_t index, uint8_t sub, uint32_t value, int bytes) {
  CanFrame f;
  f.id = cob::sdo_rx(node);
  f.dlc = 8;
  f.data[0] = expedited_download_cs(bytes);
  put_u16(f.data + 1, index);
  f.data[3] = sub;
  for (int i = 0; i < bytes; ++i) f.data[4 + i] = uint8_t(value >> (8 * i));
  return f;
}
CanFrame upload_request(uint8_t node, uint16_t index, uint8_t sub) {
  CanFrame f;
  f.id = cob::sdo_rx(node);
  f.dlc = 8;
  f.data[0] = 0x40;  // ccs = 2
  put_u16(f.data + 1, index);
  f.data[3] = sub;
  return f;
}
CanFrame abort_frame(uint32_t cob_id, uint16_t index, uint8_t sub, uint32_t code) {
  CanFrame f;
  f.id = cob_id;
  f.dlc = 8;
  f.data[0] = kAbort;
  put_u16(f.data + 1, index);
  f.data[3] = sub;
  put_u32(f.data + 4, code);
  return f;
}
}  // namespace sdo

void SdoClient::download(int64_t now, uint16_t index, uint8_t sub, std::span<const uint8_t> d, FrameBuffer& tx) {
  index_ = index;
  sub_ = sub;
  error_ = {};
  size_ = std::min(d.size(), kMaxData);
  std::copy_n(d.begin(), size_, data_.begin());
  offset_ = 0;
  toggle_ = false;
  status_ = Status::Busy;
  deadline_us_ = now + timeout_us_;
  CanFrame f;
  f.id = cob::sdo_rx(node_);
  f.dlc = 8;
  put_u16(f.data + 1, index);
  f.data[3] = sub;
  if (size_ >= 1 && size_ <= 4) {
    f.data[0] = sdo::expedited_download_cs(static_cast<int>(size_));
    std::copy_n(data_.begin(), size_, f.data + 4);
  } else {
    f.data[0] = 0x21;  // initiate segmented download, size indicated
    put_u32(f.data + 4, static_cast<uint32_t>(size_));
  }
  op_ = Op::DownloadInit;
  tx.push(f);
}

void SdoClient::download_u32(int64_t now, uint16_t index, uint8_t sub, uint32_t value, int bytes, FrameBuffer& tx) {
  uint8_t b[4];
  put_u32(b, value);
  download(now, index, sub, std::span<const uint8_t>(b, static_cast<std::size_t>(bytes)), tx);
}

void SdoClient::upload(int64_t now, uint16_t index, uint8_t sub, FrameBuffer& tx) {
  index_ = index;
  sub_ = sub;
  error_ = {};
  size_ = 0;
  toggle_ = false;
  status_ = Status::Busy;
  deadline_us_ = now + timeout_us_;
  op_ = Op::UploadInit;
  tx.push(sdo::upload_request(node_, index, sub));
}

uint32_t SdoClient::value_u32() const {
  uint32_t v = 0;
  for (std::size_t i = 0; i < size_ && i < 4; ++i) v |= uint32_t(data_[i]) << (8 * i);
  return v;
}

void SdoClient::fail(ErrorCode c, uint32_t value, int64_t now, FrameBuffer* tx, uint32_t abort_to_send) {
  status_ = Status::Failed;
  op_ = Op::None;
  error_ = Error{c, node_, index_, sub_, value, 0, now};
  if (tx && abort_to_send) tx->push(sdo::abort_frame(cob::sdo_rx(node_), index_, sub_, abort_to_send));
}

void SdoClient::send_segment(FrameBuffer& tx) {
  CanFrame f;
  f.id = cob::sdo_rx(node_);
  f.dlc = 8;
  const std::size_t n = std::min<std::size_t>(7, size_ - offset_);
  const bool last = offset_ + n >= size_;
  // ccs = 0, t (bit 4), n = 7 - bytes (bits 3-1), c = last (bit 0)
  f.data[0] = static_cast<uint8_t>((toggle_ ? 0x10 : 0) | ((7 - n) << 1) | (last ? 1 : 0));
  std::copy_n(data_.begin() + static_cast<std::ptrdiff_t>(offset_), n, f.data + 1);
  offset_ += n;
  tx.push(f);
}

bool SdoClient::on_frame(int64_t now, const CanFrame& f, FrameBuffer& tx) {
  if (f.id != cob::sdo_tx(node_)) return false;
  if (status_ != Status::Busy) return true;  // stale answer: ignore
  if (f.dlc < 8) {
    fail(ErrorCode::SdoProtocol, f.data[0], now, &tx, 0x05040001);
    return true;
  }
  const uint8_t cs = f.data[0];
  if (cs == sdo::kAbort) {
    fail(ErrorCode::SdoAbort, get_u32(f.data + 4), now, nullptr, 0);
    return true;
  }
  const bool addr_ok = get_u16(f.data + 1) == index_ && f.data[3] == sub_;
  deadline_us_ = now + timeout_us_;
  switch (op_) {
    case Op::DownloadInit:
      if (cs != 0x60 || !addr_ok) return fail(ErrorCode::SdoProtocol, cs, now, &tx, 0x05040001), true;
      if (size_ <= 4 && size_ >= 1) {
        status_ = Status::Done;
        op_ = Op::None;
      } else {
        op_ = Op::DownloadSegment;
        send_segment(tx);
      }
      return true;
    case Op::DownloadSegment: {
      // scs = 1 (0x20) with the toggle bit of the segment we sent
      const bool t = (cs & 0x10) != 0;
      if ((cs & 0xE0) != 0x20 || t != toggle_) return fail(ErrorCode::SdoProtocol, cs, now, &tx, 0x05030000), true;
      if (offset_ >= size_) {
        status_ = Status::Done;
        op_ = Op::None;
      } else {
        toggle_ = !toggle_;
        send_segment(tx);
      }
      return true;
    }
    case Op::UploadInit: {
      if ((cs & 0xE0) != 0x40 || !addr_ok) return fail(ErrorCode::SdoProtocol, cs, now, &tx, 0x05040001), true;
      if (cs & 0x02) {  // expedited
        const std::size_t n = (cs & 0x01) ? 4 - ((cs >> 2) & 0x3) : 4;
        std::copy_n(f.data + 4, n, data_.begin());
        size_ = n;
        status_ = Status::Done;
        op_ = Op::None;
      } else {
        size_ = 0;
        op_ = Op::UploadSegment;
        toggle_ = false;
        CanFrame r;
        r.id = cob::sdo_rx(node_);
        r.dlc = 8;
        r.data[0] = 0x60;  // ccs = 3, t = 0
        tx.push(r);
      }
      return true;
    }
    case Op::UploadSegment: {
      const bool t = (cs & 0x10) != 0;
      if ((cs & 0xE0) != 0x00 || t != toggle_) return fail(ErrorCode::SdoProtocol, cs, now, &tx, 0x05030000), true;
      const std::size_t n = 7 - ((cs >> 1) & 0x7);
      if (size_ + n > kMaxData) return fail(ErrorCode::SdoProtocol, cs, now, &tx, 0x05040005), true;
      std::copy_n(f.data + 1, n, data_.begin() + static_cast<std::ptrdiff_t>(size_));
      size_ += n;
      if (cs & 0x01) {
        status_ = Status::Done;
        op_ = Op::None;
      } else {
        toggle_ = !toggle_;
        CanFrame r;
        r.id = cob::sdo_rx(node_);
        r.dlc = 8;
        r.data[0] = static_cast<uint8_t>(0x60 | (toggle_ ? 0x10 : 0));
        tx.push(r);
      }
      return true;
    }
    case Op::None: break;
  }
  return true;
}

void SdoClient::poll(int64_t now, FrameBuffer& tx) {
  if (status_ == Status::Busy && now >= deadline_us_) fail(ErrorCode::SdoTimeout, 0, now, &tx, 0x05040000);
}

}  // namespace manip::canopen
