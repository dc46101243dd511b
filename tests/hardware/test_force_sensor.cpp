// The force-sensor boundary (tare, saturation, staleness, rotation) against
// hand-computed values, and the ATI Net F/T RDT client against a fake sensor
// server on loopback through real UDP sockets: the start request, records,
// lost and late datagrams, a silent sensor (stale -> communication fault).
#include <catch2/catch.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <thread>

#include "manip/hardware/force_sensor.hpp"

#include <memory>

namespace hw = manip::hardware;
using manip::Vec2;

TEST_CASE("force boundary: tare over the first samples, then bias removed", "[force_sensor]") {
  hw::ForceBoundaryParams p;
  p.tare_samples = 4;
  hw::ForceBoundary b(p);
  const Vec2 s[4] = {{1.0, -2.0}, {1.2, -2.2}, {0.8, -1.8}, {1.0, -2.0}};  // mean (1.0, -2.0)
  for (int i = 0; i < 4; ++i) {
    const auto& o = b.update({s[i], std::uint64_t(i + 1), false}, true);
    CHECK(o.taring);
    CHECK(o.f_workspace_n.norm() == 0.0);
    CHECK(o.seq == std::uint64_t(i + 1));
  }
  CHECK(b.bias_n()[0] == Approx(1.0));
  CHECK(b.bias_n()[1] == Approx(-2.0));
  const auto& o = b.update({Vec2(6.0, 3.0), 5, false}, true);
  CHECK_FALSE(o.taring);
  CHECK(o.f_workspace_n[0] == Approx(5.0));
  CHECK(o.f_workspace_n[1] == Approx(5.0));
  b.begin_session();  // a new session takes a new bias
  CHECK(b.update({Vec2(6.0, 3.0), 6, false}, true).taring);
}

TEST_CASE("force boundary: rotation into the workspace frame", "[force_sensor]") {
  hw::ForceBoundaryParams p;
  p.tare = false;
  p.rotation_deg = 90.0;  // sensor x axis = workspace x2
  hw::ForceBoundary b(p);
  const auto& o = b.update({Vec2(2.0, 0.5), 1, false}, true);
  CHECK(o.f_workspace_n[0] == Approx(-0.5));
  CHECK(o.f_workspace_n[1] == Approx(2.0));
  hw::ForceBoundaryParams q = p;
  q.rotation_deg = -30.0;
  hw::ForceBoundary c(q);
  const auto& r = c.update({Vec2(1.0, 0.0), 1, false}, true);
  CHECK(r.f_workspace_n[0] == Approx(std::sqrt(3.0) / 2));
  CHECK(r.f_workspace_n[1] == Approx(-0.5));
}

TEST_CASE("force boundary: saturation at full scale survives the bias", "[force_sensor]") {
  hw::ForceBoundaryParams p;
  p.tare_samples = 1;
  p.full_scale_n = 100.0;
  hw::ForceBoundary b(p);
  b.update({Vec2(3.0, 0.0), 1, false}, true);  // bias (3, 0)
  auto o = b.update({Vec2(150.0, 10.0), 2, false}, true);
  CHECK(o.saturated);
  CHECK(o.f_workspace_n[0] == 100.0);  // at full scale, not 97 N: the supervisor must see it
  CHECK(o.f_workspace_n[1] == Approx(10.0));
  o = b.update({Vec2(-100.0, 0.0), 3, false}, true);
  CHECK(o.saturated);
  CHECK(o.f_workspace_n[0] == -100.0);
  o = b.update({Vec2(99.0, 0.0), 4, false}, true);
  CHECK_FALSE(o.saturated);
  CHECK(o.f_workspace_n[0] == Approx(96.0));
}

TEST_CASE("force boundary: stale after N cycles without a usable sample, or on sensor error", "[force_sensor]") {
  hw::ForceBoundaryParams p;
  p.tare = false;
  p.stale_cycles = 3;
  hw::ForceBoundary b(p);
  CHECK_FALSE(b.update({Vec2(1, 1), 1, false}, true).stale);
  CHECK_FALSE(b.update({Vec2(1, 1), 1, false}, false).stale);
  CHECK_FALSE(b.update({Vec2(1, 1), 1, false}, false).stale);
  const auto& o = b.update({Vec2(1, 1), 1, false}, false);
  CHECK(o.stale);
  CHECK(o.seq == 1);  // the sequence stops advancing: the supervisor's staleness check agrees
  CHECK_FALSE(b.update({Vec2(1, 1), 2, false}, true).stale);
  CHECK(b.update({Vec2(1, 1), 3, true}, true).stale);                       // sensor error
  CHECK(b.update({Vec2(std::nan(""), 1), 4, false}, true).seq == 2);        // NaN is not a sample
}

TEST_CASE("Net F/T RDT: request and record encodings (ATI manual byte layout)", "[force_sensor]") {
  std::uint8_t req[hw::kRdtRequestBytes];
  hw::encode_rdt_request(hw::kRdtStartRealtime, 0, req);
  const std::uint8_t want[8] = {0x12, 0x34, 0x00, 0x02, 0, 0, 0, 0};
  for (int i = 0; i < 8; ++i) CHECK(req[i] == want[i]);
  hw::RdtRecord r;
  r.rdt_sequence = 0x01020304;
  r.ft_sequence = 7;
  r.status = 0;
  r.ft[0] = -1000000;
  r.ft[5] = 42;
  std::uint8_t rec[hw::kRdtRecordBytes];
  hw::encode_rdt_record(r, rec);
  CHECK(rec[0] == 0x01);
  CHECK(rec[3] == 0x04);
  CHECK(rec[12] == 0xFF);  // -1e6 = 0xFFF0BDC0 big-endian
  CHECK(rec[13] == 0xF0);
  CHECK(rec[14] == 0xBD);
  CHECK(rec[15] == 0xC0);
  hw::RdtRecord d;
  REQUIRE(hw::decode_rdt_record(rec, sizeof rec, d));
  CHECK(d.rdt_sequence == r.rdt_sequence);
  CHECK(d.ft[0] == -1000000);
  CHECK(d.ft[5] == 42);
  CHECK_FALSE(hw::decode_rdt_record(rec, 35, d));
}

namespace {
// A fake Net F/T on 127.0.0.1: answers the start request by remembering the
// client's address, then sends the records the test asks for.
struct FakeNetFt {
  int fd{-1};
  std::uint16_t port{0};
  sockaddr_in client{};
  bool have_client{false};
  std::uint8_t last_request[8]{};
  FakeNetFt() {
    fd = ::socket(AF_INET, SOCK_DGRAM, 0);
    REQUIRE(fd >= 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = 0;
    REQUIRE(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
    socklen_t len = sizeof a;
    REQUIRE(::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) == 0);
    port = ntohs(a.sin_port);
    timeval tv{1, 0};
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  }
  ~FakeNetFt() { ::close(fd); }
  bool wait_request() {
    socklen_t len = sizeof client;
    const ssize_t n = ::recvfrom(fd, last_request, sizeof last_request, 0, reinterpret_cast<sockaddr*>(&client), &len);
    have_client = n == 8;
    return have_client;
  }
  void send(std::uint32_t seq, double fx_n, double fy_n, std::uint32_t status = 0, double cpf = 1e6) {
    hw::RdtRecord r;
    r.rdt_sequence = seq;
    r.ft_sequence = seq;
    r.status = status;
    r.ft[0] = static_cast<std::int32_t>(std::lround(fx_n * cpf));
    r.ft[1] = static_cast<std::int32_t>(std::lround(fy_n * cpf));
    std::uint8_t b[hw::kRdtRecordBytes];
    hw::encode_rdt_record(r, b);
    REQUIRE(::sendto(fd, b, sizeof b, 0, reinterpret_cast<sockaddr*>(&client), sizeof client) == sizeof b);
  }
};

// Poll until something arrives (loopback delivery is fast but not synchronous).
bool poll_fresh(hw::NetFtClient& c, hw::ForceSample& s) {
  for (int i = 0; i < 200; ++i) {
    if (c.poll(s)) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return false;
}
}  // namespace

TEST_CASE("Net F/T client against a fake sensor over loopback UDP", "[force_sensor][netft]") {
  FakeNetFt srv;
  hw::NetFtClient c("127.0.0.1", srv.port, 1e6);
  std::string err;
  REQUIRE(c.start(err));
  REQUIRE(srv.wait_request());
  CHECK(srv.last_request[0] == 0x12);
  CHECK(srv.last_request[1] == 0x34);
  CHECK(srv.last_request[3] == 0x02);  // start real-time streaming

  hw::ForceSample s;
  srv.send(1, 2.5, -1.25);
  REQUIRE(poll_fresh(c, s));
  CHECK(s.f_sensor_n[0] == Approx(2.5));
  CHECK(s.f_sensor_n[1] == Approx(-1.25));
  CHECK(s.seq == 1);

  SECTION("several queued records: the newest wins") {
    srv.send(2, 1.0, 0.0);
    srv.send(3, 3.0, 0.0);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    REQUIRE(c.poll(s));
    CHECK(s.seq == 3);
    CHECK(s.f_sensor_n[0] == Approx(3.0));
    CHECK(c.lost() == 0);
  }
  SECTION("lost datagrams are counted from the RDT sequence gap") {
    srv.send(5, 1.0, 0.0);  // 2, 3, 4 lost
    REQUIRE(poll_fresh(c, s));
    CHECK(c.lost() == 3);
    CHECK(s.seq == 5);
  }
  SECTION("a late (older) datagram is dropped, not used") {
    srv.send(4, 4.0, 0.0);
    REQUIRE(poll_fresh(c, s));
    srv.send(3, -9.0, 0.0);  // arrives after 4
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    CHECK_FALSE(c.poll(s));
    CHECK(c.late() == 1);
    CHECK(s.f_sensor_n[0] == Approx(4.0));
  }
  SECTION("a silent sensor becomes stale in the boundary; a status error is stale at once") {
    hw::ForceBoundaryParams p;
    p.tare = false;
    p.stale_cycles = 5;
    hw::ForceBoundary b(p);
    int cycles_to_stale = -1;
    for (int i = 1; i <= 20; ++i) {  // 20 control cycles, no datagram
      const bool fresh = c.poll(s);
      if (b.update(s, fresh).stale) {
        cycles_to_stale = i;
        break;
      }
    }
    CHECK(cycles_to_stale == 5);
    srv.send(2, 1.0, 1.0);
    REQUIRE(poll_fresh(c, s));
    CHECK_FALSE(b.update(s, true).stale);
    srv.send(3, 1.0, 1.0, 0x80000000u);  // status word: sensor error
    REQUIRE(poll_fresh(c, s));
    CHECK(s.error);
    CHECK(b.update(s, true).stale);
  }
  c.stop();
  REQUIRE(srv.wait_request());
  CHECK(srv.last_request[3] == 0x00);  // stop streaming
}

TEST_CASE("Net F/T client: bad address refused at start with a reason", "[force_sensor][netft]") {
  hw::NetFtClient c("not-an-ip", 49152, 1e6);
  std::string err;
  CHECK_FALSE(c.start(err));
  CHECK(err.find("not an IPv4 address") != std::string::npos);
}

namespace {
// The jr3pci device layer, faked: scripted full scales and readings, failures on demand.
struct FakeJr3 final : hw::Jr3Device {
  bool opened{false}, fail_open{false}, fail_read{false};
  hw::Jr3FullScales fs{};
  hw::Jr3SixAxis next{};
  int last_filter{-1};
  bool open(std::string& error) override {
    if (fail_open) error = "JR3 /dev/jr3: No such file or directory";
    opened = !fail_open;
    return opened;
  }
  bool full_scales(hw::Jr3FullScales& out) override {
    out = fs;
    return opened;
  }
  bool read_filter(int filter, hw::Jr3SixAxis& out) noexcept override {
    last_filter = filter;
    if (fail_read) return false;
    out = next;
    return true;
  }
};
}  // namespace

TEST_CASE("JR3 source: DSP counts scaled by full scale / 16384, failed reads are stale", "[force_sensor][jr3]") {
  auto dev = std::make_unique<FakeJr3>();
  FakeJr3* d = dev.get();
  d->fs.f[0] = 100;  // N (67M25A-class full scales)
  d->fs.f[1] = 200;
  d->fs.f[2] = 200;
  hw::Jr3Source src(std::move(dev), 1);
  std::string err;
  REQUIRE(src.start(err));
  d->next.f[0] = 8192;    // half of full scale
  d->next.f[1] = -4096;   // -1/4
  hw::ForceSample s;
  REQUIRE(src.poll(s));
  CHECK(d->last_filter == 1);
  CHECK(s.f_sensor_n[0] == Approx(50.0));
  CHECK(s.f_sensor_n[1] == Approx(-50.0));
  CHECK(s.seq == 1);
  hw::ForceBoundaryParams p;
  p.tare = false;
  p.stale_cycles = 3;
  hw::ForceBoundary b(p);
  CHECK_FALSE(b.update(s, true).stale);
  d->fail_read = true;
  bool stale = false;
  for (int i = 0; i < 3; ++i) {
    const bool fresh = src.poll(s);
    CHECK_FALSE(fresh);
    stale = b.update(s, fresh).stale;
  }
  CHECK(stale);
  CHECK(s.seq == 1);
}

TEST_CASE("JR3 source: start fails with a reason (no device, zero full scales, bad filter)", "[force_sensor][jr3]") {
  std::string err;
  {
    auto dev = std::make_unique<FakeJr3>();
    dev->fail_open = true;
    hw::Jr3Source src(std::move(dev), 0);
    CHECK_FALSE(src.start(err));
    CHECK(err.find("/dev/jr3") != std::string::npos);
  }
  {
    hw::Jr3Source src(std::make_unique<FakeJr3>(), 0);  // full scales 0: sensor not connected
    CHECK_FALSE(src.start(err));
    CHECK(err.find("full scales") != std::string::npos);
  }
  {
    hw::Jr3Source src(std::make_unique<FakeJr3>(), 7);
    CHECK_FALSE(src.start(err));
    CHECK(err.find("filter 7") != std::string::npos);
  }
  {
    hw::Jr3PciDevice real("/nonexistent/jr3");
    CHECK_FALSE(real.open(err));
    CHECK(err.find("jr3pci driver") != std::string::npos);
  }
}
