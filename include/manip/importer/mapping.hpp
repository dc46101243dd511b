#pragma once
// The YAML mapping of manip_import (docs/import.md, config/import-*.yaml):
// which variable (MAT) or column (CSV) of a recording made with another rig is
// time, handle position, handle force and perturbation force, in which units
// and frame, where trials start and end and where the perturbation starts,
// and the session constants that travel in session_t. Read strictly
// (common/yaml_reader.hpp): unknown and duplicate keys are refused, and every
// later error about the data names the mapping's file, line and key.
#include <array>
#include <limits>
#include <string>
#include <vector>

#include "manip/common/types.hpp"
#include "manip/schema/session_description.hpp"

namespace manip::importer {

// Where in the mapping a setting came from, for messages:
// "mapping.yaml:12: signals.position".
struct Where {
  std::string file;
  int line{0};  // 1-based; 0 = unknown
  std::string key;
  [[nodiscard]] std::string str() const;
};

// A two-component signal: one N x k matrix variable and two of its (1-based)
// columns, or two vector variables (N x 1 or 1 x N).
struct SignalSpec {
  Where where;
  std::vector<std::string> variables;  // 1 (matrix) or 2 (one per component)
  std::array<int, 2> columns{1, 2};    // with one variable
  double to_si{1.0};                   // multiply by this to get SI (from `unit`)
  std::string unit;
};

// Sample positions of an event: a flag column (nonzero on a sample; a run of
// nonzero samples counts once, at its first sample), 1-based sample indices
// (MATLAB's), or times in the unit of the time variable.
struct MarkerSpec {
  enum class As { kFlag, kIndex, kTime };
  Where where;
  std::string variable;
  As as{As::kFlag};
};

struct Mapping {
  std::string file;
  std::string text;  // the mapping itself, copied into session_t.config_yaml

  // Time: a variable (strictly increasing, uniform) or a fixed sample rate.
  Where time_where;
  std::string time_variable;  // empty: sample_rate_hz given
  double time_to_s{1.0};
  double sample_rate_hz{0.0};
  double max_jitter{0.05};  // allowed |dt - dt_mean| / dt_mean

  SignalSpec position, handle_force, perturbation_force;

  // Recorded frame -> the log's workspace frame: workspace axis i is
  // sign_i * recorded component |axes[i]| (e.g. [-2, 1]); the workspace
  // origin is the recording's zero. Then session_t's rigid transform.
  Where axes_where;
  std::array<int, 2> axes{1, 2};
  WorkspaceToShoulder frame{};

  // Trials: from a trial-index variable, or from start/end markers.
  enum class TrialMode { kIndex, kMarkers };
  TrialMode trial_mode{TrialMode::kIndex};
  Where index_where;
  std::string index_variable;
  double index_outside{-1.0};  // this value (and NaN, and values below `first`) = between trials
  long long index_first{0};    // the recorded index of the first trial (1 for MATLAB-style numbering)
  MarkerSpec start, end;

  // Onset: first crossing of a threshold, or a marker.
  enum class OnsetMode { kThreshold, kMarker };
  OnsetMode onset_mode{OnsetMode::kThreshold};
  Where onset_where;
  double threshold_n{0.5};
  double zero_n{0.0};
  MarkerSpec onset;

  // Perturbation angle (shoulder frame, counter-clockwise from +x1).
  enum class AngleMode { kFromForce, kVariable };
  AngleMode angle_mode{AngleMode::kFromForce};
  Where angle_where;
  double angle_round_deg{1.0};
  std::string angle_variable;
  double angle_to_rad{1.0};

  // Targets written into the trial events (NaN when not given).
  Vec2 start_shoulder_m{Vec2::Constant(std::numeric_limits<double>::quiet_NaN())};
  Vec2 goal_shoulder_m{Vec2::Constant(std::numeric_limits<double>::quiet_NaN())};

  // Session constants; sample_rate_hz is filled in from the time base, frame
  // from `frame`.
  schema::SessionDescription session;
  bool drive_rate_given{false};
};

// Throws manip::ConfigError "<file>:<line>: <key>: <reason>".
Mapping load_mapping(const std::string& path);
Mapping parse_mapping(const std::string& text, const std::string& file);

}  // namespace manip::importer
