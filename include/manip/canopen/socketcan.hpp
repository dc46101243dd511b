#pragma once
// SocketCAN transport: raw CAN socket, non-blocking, receive filters, error
// frames. The kernel-frame translation and the filter sets are pure functions
// (unit-tested on machines without AF_CAN); open() reports a clear error when
// the kernel has no CAN support or the interface does not exist.
#include <linux/can.h>

#include <memory>
#include <string>
#include <vector>

#include "manip/canopen/frame.hpp"

namespace manip::canopen {

// struct can_frame <-> CanFrame. Error frames (CAN_ERR_FLAG) become CanFrame
// with kError and id = the error class bits; extended-id frames are not
// CANopen (CAN 2.0A): from_kernel marks them with id 0xFFFFFFFF so they are ignored.
CanFrame from_kernel(const can_frame& k);
can_frame to_kernel(const CanFrame& f);

// Receive filters (CAN_RAW_FILTER) of the master: EMCY, TPDO1-2, SDO answers
// and heartbeats of every node id (so an unexpected node is seen), nothing else.
std::vector<can_filter> master_filters();
// Receive filters of a (simulated) drive with this node id: NMT, SYNC, its
// RPDOs and SDO requests, and every heartbeat (heartbeat consumer).
std::vector<can_filter> drive_filters(uint8_t node_id);
// Error classes subscribed with CAN_RAW_ERR_FILTER.
can_err_mask_t error_mask();

class SocketCanPort : public CanPort {
 public:
  // nullptr and `error` set ("socket(AF_CAN): Address family not supported
  // by protocol (kernel without CAN support?)", "interface can0: No such device").
  static std::unique_ptr<SocketCanPort> open(const std::string& iface, const std::vector<can_filter>& filters,
                                             std::string& error);
  ~SocketCanPort() override;
  SocketCanPort(const SocketCanPort&) = delete;
  SocketCanPort& operator=(const SocketCanPort&) = delete;
  bool send(const CanFrame& f) override;
  std::size_t receive(std::span<CanFrame> out) override;
  int fd() const { return fd_; }

 private:
  explicit SocketCanPort(int fd) : fd_(fd) {}
  int fd_ = -1;
};

}  // namespace manip::canopen
