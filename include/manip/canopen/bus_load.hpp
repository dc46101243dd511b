#pragma once
// Worst-case CAN bus load of a configuration, from its frames.
// CAN 2.0A data frame: 47 + 8n bit times (SOF, 11-bit id, RTR, IDE, r0, DLC,
// data, CRC 15, CRC delimiter, ACK slot + delimiter, EOF 7, intermission 3)
// plus at most floor((34 + 8n - 1) / 4) stuff bits (stuffing covers the
// 34 + 8n bits from SOF to the end of the CRC; worst case one stuff bit per
// four after the first five).
#include <cstdint>
#include <string>
#include <vector>

#include "manip/canopen/config.hpp"

namespace manip::canopen {

constexpr int frame_bits_nominal(int data_bytes) { return 47 + 8 * data_bytes; }
constexpr int frame_stuff_bits_max(int data_bytes) { return (34 + 8 * data_bytes - 1) / 4; }
constexpr int frame_bits_worst(int data_bytes) {
  return frame_bits_nominal(data_bytes) + frame_stuff_bits_max(data_bytes);
}

struct BudgetLine {
  std::string what;
  int data_bytes = 0;
  int bits_per_frame = 0;  // worst case
  double frames_per_s = 0;
  double bits_per_s() const { return bits_per_frame * frames_per_s; }
};

struct BusBudget {
  std::string bus;
  std::string interface;
  uint32_t bitrate = 0;
  double sync_period_us = 0;
  std::vector<BudgetLine> lines;
  int cyclic_bits_per_sync = 0;  // SYNC + every PDO of one period, worst case
  double bits_per_s = 0;
  double load = 0;                // bits_per_s / bitrate
  double limit = 0;
  bool ok() const { return load <= limit; }
  std::string table() const;
};

std::vector<BusBudget> compute_budgets(const CanConfig& cfg);

}  // namespace manip::canopen
