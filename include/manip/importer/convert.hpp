#pragma once
// A recording of another rig (dataset.hpp) plus its mapping (mapping.hpp)
// becomes a manip session: the session message, one MANIP_STATE per sample
// and START/ONSET/END trial events, streamed into any SessionHandler (a log
// writer, or the estimator's TrialAssembler directly). What a foreign
// recording does not have is written as NaN (docs/import.md lists it):
// velocity, the admittance reference (x_ref, xd_ref, xdd_ref) and the motor
// force. estimate_impedance needs none of them (it uses position, handle
// force and perturbation force of each trial from START to END, the ONSET
// cycle, and the session constants).
#include <cstdint>
#include <string>
#include <vector>

#include "manip/common/types.hpp"
#include "manip/importer/dataset.hpp"
#include "manip/importer/mapping.hpp"
#include "manip/logging/session_stream.hpp"

namespace manip::importer {

struct ImportSummary {
  std::string input_format;
  std::int64_t samples{0};
  double sample_rate_hz{0.0};
  double duration_s{0.0};
  int trials{0};
  int perturbed{0};
  // Mean hand position at the trials' first and last samples, shoulder frame:
  // a check of the frame mapping (a reach runs along +x2, ~0.30 -> 0.55 m).
  Vec2 mean_start_shoulder_m{Vec2::Zero()}, mean_end_shoulder_m{Vec2::Zero()};
  std::vector<std::string> notes;  // things worth telling the user (one line each)
};

// Throws manip::ConfigError (the mapping does not fit the data: a variable
// missing or of the wrong size, ...) or manip::InputError (the data itself is
// unusable: time not increasing, a marker outside every trial, ...); every
// message names the mapping's file:line: key and the data file and variable.
ImportSummary convert(const Mapping& m, const Dataset& ds, logging::SessionHandler& out);

// manip_import: mapping file + MAT/CSV file -> LCM log through AtomicOutput
// (never clobbers without force; nothing left behind on failure).
ImportSummary import_session(const std::string& mapping_path, const std::string& input_path,
                             const std::string& out_path, bool force);

}  // namespace manip::importer
