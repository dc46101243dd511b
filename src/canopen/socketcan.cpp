#include "manip/canopen/socketcan.hpp"

#include <fcntl.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace manip::canopen {

CanFrame from_kernel(const can_frame& k) {
  CanFrame f;
  f.dlc = k.can_dlc > 8 ? 8 : k.can_dlc;
  std::memcpy(f.data, k.data, f.dlc);
  if (k.can_id & CAN_ERR_FLAG) {
    f.flags = CanFrame::kError;
    f.id = k.can_id & CAN_ERR_MASK;
    f.dlc = 8;  // error frames always carry 8 bytes of detail
    std::memcpy(f.data, k.data, 8);
    return f;
  }
  if (k.can_id & CAN_EFF_FLAG) {
    f.id = 0xFFFFFFFFu;
    return f;
  }
  f.id = k.can_id & CAN_SFF_MASK;
  if (k.can_id & CAN_RTR_FLAG) f.flags |= CanFrame::kRtr;
  return f;
}

can_frame to_kernel(const CanFrame& f) {
  can_frame k{};
  k.can_id = f.id & CAN_SFF_MASK;
  if (f.is_rtr()) k.can_id |= CAN_RTR_FLAG;
  k.can_dlc = f.dlc > 8 ? 8 : f.dlc;
  std::memcpy(k.data, f.data, k.can_dlc);
  return k;
}

std::vector<can_filter> master_filters() {
  const canid_t m = CAN_SFF_MASK & 0x780;  // function code only: every node id
  return {{0x080, m | CAN_RTR_FLAG}, {0x180, m | CAN_RTR_FLAG}, {0x280, m | CAN_RTR_FLAG},
          {0x580, m | CAN_RTR_FLAG}, {0x700, m | CAN_RTR_FLAG}};
}

std::vector<can_filter> drive_filters(uint8_t node) {
  const canid_t exact = CAN_SFF_MASK | CAN_RTR_FLAG;
  std::vector<can_filter> v = {{0x000, exact}, {0x080, exact}, {cob::sdo_rx(node), exact}, {0x700, (0x780u) | CAN_RTR_FLAG}};
  for (int n = 0; n < 4; ++n) v.push_back({cob::rpdo(n, node), exact});
  return v;
}

can_err_mask_t error_mask() {
  return CAN_ERR_TX_TIMEOUT | CAN_ERR_CRTL | CAN_ERR_TRX | CAN_ERR_ACK | CAN_ERR_BUSOFF | CAN_ERR_RESTARTED;
}

std::unique_ptr<SocketCanPort> SocketCanPort::open(const std::string& iface, const std::vector<can_filter>& filters,
                                                   std::string& error) {
  const int fd = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0) {
    error = std::string("socket(AF_CAN): ") + std::strerror(errno) +
            (errno == EAFNOSUPPORT ? " (kernel without CAN support: load can, can-raw, can-dev)" : "");
    return nullptr;
  }
  if (iface.size() >= IFNAMSIZ) {
    ::close(fd);
    error = "interface name too long: " + iface;
    return nullptr;
  }
  ifreq ifr{};
  std::strncpy(ifr.ifr_name, iface.c_str(), IFNAMSIZ - 1);
  if (::ioctl(fd, SIOCGIFINDEX, &ifr) < 0) {
    error = "interface " + iface + ": " + std::strerror(errno);
    ::close(fd);
    return nullptr;
  }
  if (!filters.empty() &&
      ::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_FILTER, filters.data(), static_cast<socklen_t>(filters.size() * sizeof(can_filter))) < 0) {
    error = "CAN_RAW_FILTER on " + iface + ": " + std::strerror(errno);
    ::close(fd);
    return nullptr;
  }
  const can_err_mask_t em = error_mask();
  if (::setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &em, sizeof em) < 0) {
    error = "CAN_RAW_ERR_FILTER on " + iface + ": " + std::strerror(errno);
    ::close(fd);
    return nullptr;
  }
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    error = "bind " + iface + ": " + std::strerror(errno);
    ::close(fd);
    return nullptr;
  }
  return std::unique_ptr<SocketCanPort>(new SocketCanPort(fd));
}

SocketCanPort::~SocketCanPort() {
  if (fd_ >= 0) ::close(fd_);
}

bool SocketCanPort::send(const CanFrame& f) {
  const can_frame k = to_kernel(f);
  return ::write(fd_, &k, sizeof k) == static_cast<ssize_t>(sizeof k);  // EAGAIN: tx queue full -> false
}

std::size_t SocketCanPort::receive(std::span<CanFrame> out) {
  std::size_t n = 0;
  while (n < out.size()) {
    can_frame k;
    const ssize_t r = ::read(fd_, &k, sizeof k);
    if (r != static_cast<ssize_t>(sizeof k)) break;  // EAGAIN: nothing more
    const CanFrame f = from_kernel(k);
    if (f.id == 0xFFFFFFFFu) continue;
    out[n++] = f;
  }
  return n;
}

}  // namespace manip::canopen
