#pragma once
// The handle force sensor behind the `can` backend: a source (the simulated
// sensor of --can-virtual, ATI Net F/T over UDP) and the boundary every
// source goes through once per control cycle:
//   - bias (tare): the mean of the first `tare_samples` fresh samples after
//     the session starts (enable()), hand resting on the handle; the reading
//     is zero while the bias is taken;
//   - saturation: |F| of an axis at or above the sensor's full scale is
//     reported at full scale (the safety supervisor's sensor_saturation_n must
//     not exceed it, checked at configure());
//   - staleness: `stale_cycles` control cycles without a fresh sample, or a
//     sensor-reported error, is a communication fault (backend_status
//     kBackendError) and the force sequence stops advancing;
//   - rotation: sensor frame -> workspace frame, counter-clockwise by
//     rotation_deg (the sensor's x axis in workspace coordinates).
// poll()/update() never allocate or block (sockets are non-blocking).
#include <cstdint>
#include <memory>
#include <string>

#include "manip/common/types.hpp"

namespace manip::hardware {

// One sensor sample in the sensor frame (forces only: the handle is planar).
struct ForceSample {
  Vec2 f_sensor_n{Vec2::Zero()};
  std::uint64_t seq{0};   // the sensor's own sample counter (changes with every new sample)
  bool error{false};      // the sensor reports a fault (Net F/T status word != 0)
};

class ForceSource {
 public:
  virtual ~ForceSource() = default;
  // Set-up (slow, may fail): returns false with `error`.
  virtual bool start(std::string& error) = 0;
  // Real-time: newest sample received so far (true if a new one arrived).
  virtual bool poll(ForceSample& latest) noexcept = 0;
  virtual void stop() noexcept {}
};

struct ForceBoundaryParams {
  bool tare{true};
  std::uint32_t tare_samples{200};
  double full_scale_n{200.0};
  std::uint32_t stale_cycles{20};
  double rotation_deg{0.0};
};

class ForceBoundary {
 public:
  explicit ForceBoundary(const ForceBoundaryParams& p);
  // Restart the bias estimate (session start).
  void begin_session();
  struct Out {
    Vec2 f_workspace_n{Vec2::Zero()};
    std::uint64_t seq{0};     // advances with every fresh, usable sample
    bool stale{false};        // no fresh sample for stale_cycles cycles, or sensor error
    bool saturated{false};    // an axis at or above full scale this cycle
    bool taring{false};
  };
  // Once per control cycle with the newest sample and whether it is new.
  const Out& update(const ForceSample& s, bool fresh) noexcept;
  [[nodiscard]] const Vec2& bias_n() const { return bias_n_; }
  [[nodiscard]] const Out& last() const { return out_; }

 private:
  ForceBoundaryParams p_;
  Mat2 rot_;
  Vec2 bias_n_{Vec2::Zero()};
  Vec2 bias_sum_n_{Vec2::Zero()};
  std::uint32_t bias_n_samples_{0};
  std::uint32_t since_fresh_{0};
  Out out_{};
};

// ATI Net F/T, Raw Data Transfer (RDT) over UDP (ATI Net F/T manual, ch. 9):
// request = 8 bytes big-endian {uint16 header 0x1234, uint16 command,
// uint32 sample_count} (command 2 = start high-speed real-time streaming,
// 0 = stop; count 0 = infinite); each record = 36 bytes big-endian
// {uint32 rdt_sequence, uint32 ft_sequence, uint32 status, int32 Fx, Fy, Fz,
// Tx, Ty, Tz} in counts; force [N] = counts / counts_per_force.
struct RdtRecord {
  std::uint32_t rdt_sequence{0};
  std::uint32_t ft_sequence{0};
  std::uint32_t status{0};
  std::int32_t ft[6]{};
};
constexpr std::size_t kRdtRequestBytes = 8;
constexpr std::size_t kRdtRecordBytes = 36;
constexpr std::uint16_t kRdtHeader = 0x1234;
constexpr std::uint16_t kRdtStartRealtime = 0x0002;
constexpr std::uint16_t kRdtStop = 0x0000;
void encode_rdt_request(std::uint16_t command, std::uint32_t count, std::uint8_t out[kRdtRequestBytes]);
void encode_rdt_record(const RdtRecord& r, std::uint8_t out[kRdtRecordBytes]);
bool decode_rdt_record(const std::uint8_t* data, std::size_t n, RdtRecord& out);

class NetFtClient final : public ForceSource {
 public:
  NetFtClient(std::string address, std::uint16_t port, double counts_per_force);
  ~NetFtClient() override;
  NetFtClient(const NetFtClient&) = delete;
  NetFtClient& operator=(const NetFtClient&) = delete;
  bool start(std::string& error) override;  // socket, connect, start streaming
  bool poll(ForceSample& latest) noexcept override;
  void stop() noexcept override;             // stop streaming, close

  // Counters (diagnostics and tests).
  [[nodiscard]] std::uint64_t received() const { return received_; }
  [[nodiscard]] std::uint64_t lost() const { return lost_; }   // gaps in rdt_sequence
  [[nodiscard]] std::uint64_t late() const { return late_; }   // out-of-order (older) records, dropped
  [[nodiscard]] std::uint64_t malformed() const { return malformed_; }

 private:
  std::string address_;
  std::uint16_t port_;
  double counts_per_force_;
  int fd_{-1};
  bool have_seq_{false};
  std::uint32_t last_rdt_seq_{0};
  ForceSample latest_{};
  std::uint64_t received_{0}, lost_{0}, late_{0}, malformed_{0};
};

}  // namespace manip::hardware

namespace manip::hardware {

// JR3 6-axis sensor on its PCI receiver, through the Linux `jr3pci` driver's
// character device (/dev/jr3, one per channel): ioctl magic 'k',
//   IOCTL0_JR3_FILTER0..6 = _IOR('k', 1..7, six_axis_array{int f[3]; int m[3]})
//   IOCTL0_JR3_ZEROOFFS   = _IO('k', 8)
//   IOCTL0_JR3_GET_FULL_SCALES = _IOR('k', 9, force_array{int f[3]; int m[3]; int v[2]})
// Values are in DSP units: force [N] = value * full_scale / 16384 (the JR3
// DSP's full-scale count; full scales in N, moments in N dm per the sensor's
// calibration). The driver offers no sample counter: a successful read is a
// fresh sample, a failed ioctl is not (the boundary turns that into staleness).
struct Jr3SixAxis {
  std::int32_t f[3]{};
  std::int32_t m[3]{};
};
struct Jr3FullScales {
  std::int32_t f[3]{};
  std::int32_t m[3]{};
  std::int32_t v[2]{};
};
constexpr double kJr3FullScaleCounts = 16384.0;

// The device layer (real: Jr3PciDevice; tests: a fake).
class Jr3Device {
 public:
  virtual ~Jr3Device() = default;
  virtual bool open(std::string& error) = 0;
  virtual bool full_scales(Jr3FullScales& out) = 0;
  virtual bool read_filter(int filter, Jr3SixAxis& out) noexcept = 0;  // filter 0 (unfiltered) .. 6
  virtual void close() noexcept {}
};

class Jr3PciDevice final : public Jr3Device {
 public:
  explicit Jr3PciDevice(std::string path = "/dev/jr3") : path_(std::move(path)) {}
  ~Jr3PciDevice() override { close(); }
  Jr3PciDevice(const Jr3PciDevice&) = delete;
  Jr3PciDevice& operator=(const Jr3PciDevice&) = delete;
  bool open(std::string& error) override;
  bool full_scales(Jr3FullScales& out) override;
  bool read_filter(int filter, Jr3SixAxis& out) noexcept override;
  void close() noexcept override;

 private:
  std::string path_;
  int fd_{-1};
};

class Jr3Source final : public ForceSource {
 public:
  // filter: the DSP's low-pass filter number (0 = raw, 1 = 500 Hz, 2 = 125 Hz, ...).
  Jr3Source(std::unique_ptr<Jr3Device> dev, int filter) : dev_(std::move(dev)), filter_(filter) {}
  bool start(std::string& error) override;
  bool poll(ForceSample& latest) noexcept override;
  void stop() noexcept override { dev_->close(); }
  [[nodiscard]] const Jr3FullScales& scales() const { return fs_; }

 private:
  std::unique_ptr<Jr3Device> dev_;
  int filter_;
  Jr3FullScales fs_{};
  ForceSample latest_{};
};

}  // namespace manip::hardware
