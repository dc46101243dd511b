#pragma once
// Group analysis over several logs (participants), like the paper's Table 1:
// each participant's session estimate with its 95 % interval, and the group
// mean (std) across participants (sample std, n - 1). Logs estimated with
// different configurations (settings, sample rate) are never pooled: they
// form separate groups, each said to be one.
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "manip/estimation/session_estimator.hpp"

namespace manip::estimation {

struct GroupMember {
  std::string participant;  // participant_id, with the log's stem when ids repeat
  std::string log;
  Summary session;          // the method's session summary
};

struct GroupTable {
  std::string method;
  int configuration{1};      // 1-based index of the configuration
  int n_configurations{1};
  std::string configuration_text;  // what identifies it (sample rate, settings digest)
  std::vector<GroupMember> members;
  Mat2 d_mean{Mat2::Zero()}, d_std{Mat2::Zero()}, k_mean{Mat2::Zero()}, k_std{Mat2::Zero()};
  [[nodiscard]] int n() const { return static_cast<int>(members.size()); }
};

// One table per (configuration, method). Logs without that method's session
// summary are left out of its table.
std::vector<GroupTable> group_tables(const std::vector<std::pair<std::string, Report>>& reports,
                                     const std::vector<std::string>& methods);
std::string group_text(const std::vector<GroupTable>& tables);
nlohmann::json group_json(const std::vector<GroupTable>& tables);
// Tidy long form, the columns of manipplot.group --csv (docs/report.md).
std::string group_csv(const std::vector<GroupTable>& tables);

}  // namespace manip::estimation
