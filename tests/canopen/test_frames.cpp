// Frame-level tests against bytes written out by hand from CiA 301.
#include <catch2/catch.hpp>

#include <linux/can.h>
#include <linux/can/error.h>

#include <string>

#include "manip/canopen/master.hpp"
#include "manip/canopen/sdo.hpp"
#include "manip/canopen/socketcan.hpp"

using namespace manip::canopen;

namespace {
CanFrame server(std::initializer_list<uint8_t> b) {
  CanFrame f = make_frame(0x581, b);
  return f;
}
}  // namespace

TEST_CASE("canopen frames: NMT, heartbeat, expedited SDO bytes as in CiA 301") {
  CHECK(nmt_frame(NmtCommand::Start, 1) == make_frame(0x000, {0x01, 0x01}));
  CHECK(nmt_frame(NmtCommand::ResetNode, 2) == make_frame(0x000, {0x81, 0x02}));
  // Download 0x1017:00 = 50 ms (UNSIGNED16): ccs=1, n=2, e=1, s=1 -> 0x2B.
  CHECK(sdo::expedited_download(1, 0x1017, 0, 50, 2) == make_frame(0x601, {0x2B, 0x17, 0x10, 0x00, 0x32, 0, 0, 0}));
  // Download 0x1016:01 = 0x007F0064 (consumer: node 127, 100 ms): 0x23.
  CHECK(sdo::expedited_download(1, 0x1016, 1, 0x007F0064, 4) ==
        make_frame(0x601, {0x23, 0x16, 0x10, 0x01, 0x64, 0x00, 0x7F, 0x00}));
  CHECK(sdo::expedited_download(3, 0x6060, 0, 10, 1) == make_frame(0x603, {0x2F, 0x60, 0x60, 0x00, 0x0A, 0, 0, 0}));
  CHECK(sdo::upload_request(1, 0x1000, 0) == make_frame(0x601, {0x40, 0x00, 0x10, 0x00, 0, 0, 0, 0}));
}

TEST_CASE("canopen SDO client: expedited upload of 0x1000 and abort decoding") {
  SdoClient c;
  c.set_node(1);
  FrameBuffer tx;
  c.upload(0, 0x1000, 0, tx);
  REQUIRE(tx.size() == 1);
  tx.clear();
  c.on_frame(100, server({0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00}), tx);
  REQUIRE(c.status() == SdoClient::Status::Done);
  CHECK(c.value_u32() == 0x00020192u);

  c.download_u32(200, 0x1600, 1, 0x60400010, 4, tx);
  c.on_frame(300, server({0x80, 0x00, 0x16, 0x01, 0x41, 0x00, 0x04, 0x06}), tx);
  REQUIRE(c.status() == SdoClient::Status::Failed);
  CHECK(c.error().code == ErrorCode::SdoAbort);
  CHECK(c.error().value == 0x06040041u);
  const std::string text = describe(c.error());
  CHECK(text.find("node 1") != std::string::npos);
  CHECK(text.find("0x1600:01") != std::string::npos);
  CHECK(text.find("0x06040041") != std::string::npos);
  CHECK(text.find("cannot be mapped") != std::string::npos);
}

TEST_CASE("canopen SDO client: segmented upload (0x1008 'Accelnet')") {
  SdoClient c;
  c.set_node(1);
  FrameBuffer tx;
  c.upload(0, 0x1008, 0, tx);
  tx.clear();
  // initiate upload response: scs=2, e=0, s=1 -> 0x41, size 8
  c.on_frame(1, server({0x41, 0x08, 0x10, 0x00, 0x08, 0, 0, 0}), tx);
  REQUIRE(tx.size() == 1);
  CHECK(tx[0] == make_frame(0x601, {0x60, 0, 0, 0, 0, 0, 0, 0}));  // ccs=3, t=0
  tx.clear();
  // segment t=0, n=0, c=0: 7 bytes
  c.on_frame(2, server({0x00, 'A', 'c', 'c', 'e', 'l', 'n', 'e'}), tx);
  REQUIRE(tx.size() == 1);
  CHECK(tx[0] == make_frame(0x601, {0x70, 0, 0, 0, 0, 0, 0, 0}));  // t=1
  tx.clear();
  // last segment: t=1 (0x10), n=6 (0x0C), c=1 -> 0x1D
  c.on_frame(3, server({0x1D, 't', 0, 0, 0, 0, 0, 0}), tx);
  REQUIRE(c.status() == SdoClient::Status::Done);
  const auto d = c.data();
  CHECK(std::string(reinterpret_cast<const char*>(d.data()), d.size()) == "Accelnet");
}

TEST_CASE("canopen SDO client: segmented download, toggle error, timeout aborts") {
  SdoClient c;
  c.set_node(1);
  c.set_timeout_us(1000);
  FrameBuffer tx;
  const std::string s = "0123456789";
  c.download(0, 0x2F00, 0, std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(s.data()), s.size()), tx);
  REQUIRE(tx.size() == 1);
  CHECK(tx[0] == make_frame(0x601, {0x21, 0x00, 0x2F, 0x00, 0x0A, 0, 0, 0}));
  tx.clear();
  c.on_frame(1, server({0x60, 0x00, 0x2F, 0x00, 0, 0, 0, 0}), tx);
  REQUIRE(tx.size() == 1);
  CHECK(tx[0] == make_frame(0x601, {0x00, '0', '1', '2', '3', '4', '5', '6'}));
  tx.clear();
  c.on_frame(2, server({0x20, 0, 0, 0, 0, 0, 0, 0}), tx);
  REQUIRE(tx.size() == 1);
  // t=1, n=4 (3 bytes), c=1 -> 0x10 | 0x08 | 0x01
  CHECK(tx[0] == make_frame(0x601, {0x19, '7', '8', '9', 0, 0, 0, 0}));
  tx.clear();
  SECTION("done") {
    c.on_frame(3, server({0x30, 0, 0, 0, 0, 0, 0, 0}), tx);
    CHECK(c.status() == SdoClient::Status::Done);
  }
  SECTION("wrong toggle") {
    c.on_frame(3, server({0x20, 0, 0, 0, 0, 0, 0, 0}), tx);
    CHECK(c.status() == SdoClient::Status::Failed);
    CHECK(c.error().code == ErrorCode::SdoProtocol);
    REQUIRE(tx.size() == 1);
    CHECK(tx[0] == make_frame(0x601, {0x80, 0x00, 0x2F, 0x00, 0x00, 0x00, 0x03, 0x05}));
  }
  SECTION("timeout") {
    c.poll(2 + 999, tx);
    CHECK(c.busy());
    c.poll(2 + 1000, tx);
    CHECK(c.error().code == ErrorCode::SdoTimeout);
    REQUIRE(tx.size() == 1);
    CHECK(tx[0] == make_frame(0x601, {0x80, 0x00, 0x2F, 0x00, 0x00, 0x00, 0x04, 0x05}));
    CHECK(describe(c.error()).find("timeout") != std::string::npos);
  }
}

TEST_CASE("canopen SocketCAN: kernel frames, error frames, filters, open without AF_CAN") {
  can_frame k{};
  k.can_id = 0x181;
  k.can_dlc = 6;
  k.data[0] = 0x27;
  const CanFrame f = from_kernel(k);
  CHECK(f.id == 0x181u);
  CHECK(f.dlc == 6);
  CHECK(f.data[0] == 0x27);
  CHECK(to_kernel(f).can_id == 0x181u);
  k.can_id = 0x12345 | CAN_EFF_FLAG;
  CHECK(from_kernel(k).id == 0xFFFFFFFFu);  // not CANopen: dropped by receive()

  can_frame e{};
  e.can_id = CAN_ERR_FLAG | CAN_ERR_BUSOFF;
  e.can_dlc = 8;
  CHECK(classify_error_frame(from_kernel(e)) == ErrorCode::BusOff);
  e.can_id = CAN_ERR_FLAG | CAN_ERR_CRTL;
  e.data[1] = CAN_ERR_CRTL_TX_PASSIVE;
  CHECK(from_kernel(e).is_error());
  CHECK(classify_error_frame(from_kernel(e)) == ErrorCode::BusErrorPassive);
  e.data[1] = CAN_ERR_CRTL_RX_OVERFLOW;
  CHECK(classify_error_frame(from_kernel(e)) == ErrorCode::ControllerProblem);
  e.data[1] = CAN_ERR_CRTL_RX_WARNING;
  CHECK(classify_error_frame(from_kernel(e)) == ErrorCode::None);
  e.can_id = CAN_ERR_FLAG | CAN_ERR_LOSTARB;
  CHECK(classify_error_frame(from_kernel(e)) == ErrorCode::None);
  CHECK((error_mask() & CAN_ERR_BUSOFF) != 0);

  auto passes = [](const std::vector<can_filter>& fs, uint32_t id) {
    for (const auto& x : fs)
      if ((id & x.can_mask) == (x.can_id & x.can_mask)) return true;
    return false;
  };
  const auto m = master_filters();
  for (uint32_t id : {0x081u, 0x181u, 0x1FFu, 0x282u, 0x585u, 0x701u, 0x77Fu}) CHECK(passes(m, id));
  for (uint32_t id : {0x000u, 0x201u, 0x601u, 0x381u}) CHECK_FALSE(passes(m, id));
  const auto d = drive_filters(3);
  for (uint32_t id : {0x000u, 0x080u, 0x203u, 0x303u, 0x603u, 0x77Fu}) CHECK(passes(d, id));
  for (uint32_t id : {0x201u, 0x604u, 0x183u, 0x583u}) CHECK_FALSE(passes(d, id));

  std::string err;
  auto port = SocketCanPort::open("manipnonexist0", master_filters(), err);
  CHECK(port == nullptr);
  CHECK((err.find("socket(AF_CAN)") != std::string::npos || err.find("manipnonexist0") != std::string::npos));
}

TEST_CASE("canopen EMCY policy and Copley event status text") {
  CHECK(emcy_policy(0x0000) == EmcyAction::Reset);
  CHECK(emcy_policy(0x2310) == EmcyAction::Fault);   // over-current
  CHECK(emcy_policy(0x3210) == EmcyAction::Fault);   // DC link over-voltage
  CHECK(emcy_policy(0x7305) == EmcyAction::Fault);   // encoder
  CHECK(emcy_policy(0x8611) == EmcyAction::Fault);   // following error
  CHECK(emcy_policy(0x8130) == EmcyAction::Fault);   // heartbeat
  CHECK(emcy_policy(0x4210) == EmcyAction::Warning); // device temperature
  CHECK(emcy_policy(0x8120) == EmcyAction::Warning); // error passive reported by the drive
  CHECK(copley_event_status_text(0) == "");
  CHECK(copley_event_status_text((1u << 0) | (1u << 3)) == "short circuit detected, under voltage");
  CHECK(std::string(emcy_code_text(0x2310)).find("current") != std::string::npos);
}
