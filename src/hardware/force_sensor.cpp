#include "manip/hardware/force_sensor.hpp"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <numbers>

namespace manip::hardware {

ForceBoundary::ForceBoundary(const ForceBoundaryParams& p) : p_(p) {
  const double a = p.rotation_deg * std::numbers::pi / 180.0;
  rot_ << std::cos(a), -std::sin(a), std::sin(a), std::cos(a);
  begin_session();
}

void ForceBoundary::begin_session() {
  bias_n_.setZero();
  bias_sum_n_.setZero();
  bias_n_samples_ = 0;
  since_fresh_ = 0;
  out_ = Out{};
}

const ForceBoundary::Out& ForceBoundary::update(const ForceSample& s, bool fresh) noexcept {
  const bool usable = fresh && !s.error && std::isfinite(s.f_sensor_n[0]) && std::isfinite(s.f_sensor_n[1]);
  since_fresh_ = usable ? 0 : since_fresh_ + 1;
  out_.stale = s.error || since_fresh_ >= p_.stale_cycles;
  if (!usable) return out_;  // the previous value and sequence stay: the supervisor sees staleness too
  ++out_.seq;
  // Saturation is judged on the raw sensor axes (the full scale is the sensor's).
  Vec2 raw = s.f_sensor_n;
  out_.saturated = false;
  for (int i = 0; i < 2; ++i)
    if (std::abs(raw[i]) >= p_.full_scale_n) {
      raw[i] = std::copysign(p_.full_scale_n, raw[i]);
      out_.saturated = true;
    }
  if (p_.tare && bias_n_samples_ < p_.tare_samples) {
    bias_sum_n_ += raw;
    if (++bias_n_samples_ == p_.tare_samples) bias_n_ = bias_sum_n_ / double(p_.tare_samples);
    out_.taring = true;
    out_.f_workspace_n.setZero();
    return out_;
  }
  out_.taring = false;
  Vec2 f = raw - bias_n_;
  // A saturated axis stays at full scale after the bias (the supervisor must see it).
  for (int i = 0; i < 2; ++i)
    if (std::abs(raw[i]) >= p_.full_scale_n) f[i] = raw[i];
  out_.f_workspace_n = rot_ * f;
  return out_;
}

namespace {
void put32(std::uint8_t* p, std::uint32_t v) {
  p[0] = std::uint8_t(v >> 24);
  p[1] = std::uint8_t(v >> 16);
  p[2] = std::uint8_t(v >> 8);
  p[3] = std::uint8_t(v);
}
std::uint32_t get32(const std::uint8_t* p) {
  return (std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) | (std::uint32_t(p[2]) << 8) | p[3];
}
}  // namespace

void encode_rdt_request(std::uint16_t command, std::uint32_t count, std::uint8_t out[kRdtRequestBytes]) {
  out[0] = std::uint8_t(kRdtHeader >> 8);
  out[1] = std::uint8_t(kRdtHeader & 0xFF);
  out[2] = std::uint8_t(command >> 8);
  out[3] = std::uint8_t(command & 0xFF);
  put32(out + 4, count);
}

void encode_rdt_record(const RdtRecord& r, std::uint8_t out[kRdtRecordBytes]) {
  put32(out, r.rdt_sequence);
  put32(out + 4, r.ft_sequence);
  put32(out + 8, r.status);
  for (int i = 0; i < 6; ++i) put32(out + 12 + 4 * i, static_cast<std::uint32_t>(r.ft[i]));
}

bool decode_rdt_record(const std::uint8_t* d, std::size_t n, RdtRecord& r) {
  if (n != kRdtRecordBytes) return false;
  r.rdt_sequence = get32(d);
  r.ft_sequence = get32(d + 4);
  r.status = get32(d + 8);
  for (int i = 0; i < 6; ++i) r.ft[i] = static_cast<std::int32_t>(get32(d + 12 + 4 * i));
  return true;
}

NetFtClient::NetFtClient(std::string address, std::uint16_t port, double counts_per_force)
    : address_(std::move(address)), port_(port), counts_per_force_(counts_per_force) {}

NetFtClient::~NetFtClient() { stop(); }

bool NetFtClient::start(std::string& error) {
  stop();
  sockaddr_in sa{};
  sa.sin_family = AF_INET;
  sa.sin_port = htons(port_);
  if (::inet_pton(AF_INET, address_.c_str(), &sa.sin_addr) != 1) {
    error = "Net F/T address '" + address_ + "' is not an IPv4 address";
    return false;
  }
  fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd_ < 0) {
    error = std::string("Net F/T: socket: ") + std::strerror(errno);
    return false;
  }
  // connect(): only the sensor's datagrams are received, send() needs no address.
  if (::connect(fd_, reinterpret_cast<const sockaddr*>(&sa), sizeof sa) != 0) {
    error = "Net F/T " + address_ + ":" + std::to_string(port_) + ": connect: " + std::strerror(errno);
    stop();
    return false;
  }
  std::uint8_t req[kRdtRequestBytes];
  encode_rdt_request(kRdtStartRealtime, 0, req);
  if (::send(fd_, req, sizeof req, 0) != static_cast<ssize_t>(sizeof req)) {
    error = "Net F/T " + address_ + ":" + std::to_string(port_) + ": send start request: " + std::strerror(errno);
    stop();
    return false;
  }
  have_seq_ = false;
  latest_ = ForceSample{};
  received_ = lost_ = late_ = malformed_ = 0;
  return true;
}

bool NetFtClient::poll(ForceSample& latest) noexcept {
  bool fresh = false;
  if (fd_ >= 0) {
    std::uint8_t buf[64];
    for (;;) {  // drain: only the newest record matters
      const ssize_t n = ::recv(fd_, buf, sizeof buf, MSG_DONTWAIT);
      if (n < 0) break;  // EAGAIN (nothing more) or ECONNREFUSED (sensor not there): stale
      RdtRecord r;
      if (!decode_rdt_record(buf, static_cast<std::size_t>(n), r)) {
        ++malformed_;
        continue;
      }
      if (have_seq_) {
        const auto delta = static_cast<std::int32_t>(r.rdt_sequence - last_rdt_seq_);
        if (delta <= 0) {  // older than what we have: arrived late, useless now
          ++late_;
          continue;
        }
        lost_ += static_cast<std::uint32_t>(delta - 1);
      }
      have_seq_ = true;
      last_rdt_seq_ = r.rdt_sequence;
      ++received_;
      latest_.f_sensor_n = Vec2(r.ft[0], r.ft[1]) / counts_per_force_;
      latest_.seq = r.rdt_sequence;
      latest_.error = r.status != 0;
      fresh = true;
    }
  }
  latest = latest_;
  return fresh;
}

void NetFtClient::stop() noexcept {
  if (fd_ < 0) return;
  std::uint8_t req[kRdtRequestBytes];
  encode_rdt_request(kRdtStop, 0, req);
  (void)::send(fd_, req, sizeof req, MSG_DONTWAIT);
  ::close(fd_);
  fd_ = -1;
}

}  // namespace manip::hardware

#include <fcntl.h>
#include <sys/ioctl.h>

namespace manip::hardware {

namespace {
// jr3pci-ioctl.h (magic 'k'): FILTER0..6 = 1..7, GET_FULL_SCALES = 9.
unsigned long jr3_filter_request(int filter) {
  return _IOR('k', 1 + filter, Jr3SixAxis);
}
constexpr unsigned long kJr3GetFullScales = _IOR('k', 9, Jr3FullScales);
}  // namespace

bool Jr3PciDevice::open(std::string& error) {
  close();
  fd_ = ::open(path_.c_str(), O_RDWR | O_CLOEXEC);
  if (fd_ < 0) {
    error = "JR3 " + path_ + ": " + std::strerror(errno) + " (jr3pci driver loaded? device node created?)";
    return false;
  }
  return true;
}

bool Jr3PciDevice::full_scales(Jr3FullScales& out) { return fd_ >= 0 && ::ioctl(fd_, kJr3GetFullScales, &out) == 0; }

bool Jr3PciDevice::read_filter(int filter, Jr3SixAxis& out) noexcept {
  return fd_ >= 0 && filter >= 0 && filter <= 6 && ::ioctl(fd_, jr3_filter_request(filter), &out) == 0;
}

void Jr3PciDevice::close() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

bool Jr3Source::start(std::string& error) {
  if (filter_ < 0 || filter_ > 6) {
    error = "JR3 filter " + std::to_string(filter_) + " (0..6)";
    return false;
  }
  if (!dev_->open(error)) return false;
  if (!dev_->full_scales(fs_) || fs_.f[0] <= 0 || fs_.f[1] <= 0) {
    error = "JR3: full scales unreadable or zero (sensor not connected to the receiver?)";
    dev_->close();
    return false;
  }
  latest_ = ForceSample{};
  return true;
}

bool Jr3Source::poll(ForceSample& latest) noexcept {
  Jr3SixAxis s;
  const bool ok = dev_->read_filter(filter_, s);
  if (ok) {
    latest_.f_sensor_n = Vec2(s.f[0] * fs_.f[0] / kJr3FullScaleCounts, s.f[1] * fs_.f[1] / kJr3FullScaleCounts);
    ++latest_.seq;
  }
  latest = latest_;
  return ok;
}

}  // namespace manip::hardware
