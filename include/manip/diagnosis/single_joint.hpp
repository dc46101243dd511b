#pragma once
// Single-joint position-perturbation records (position in, torque out), the
// front end of diagnose_model --single-joint. Layout (docs/diagnosis.md):
//
//   # comment lines start with '#'; one of them may carry the sample period
//   # as "dt=<seconds>" (e.g. "# dt=0.001; channels=['pos1', 'tq1']")
//   time_s,pos_rad,torque_nm      <- optional column-header line
//   0.000,0.0747,-2.74
//   ...
//
// Columns: without a header line, 2 columns are (pos_rad, torque_nm) and need
// "dt="; 3 columns are (time_s, pos_rad, torque_nm). A header line names the
// columns (any order; pos_rad and torque_nm required, time_s optional). Units
// are SI: rad, N m, s. With a time column the samples must be uniformly
// spaced (|t_i - t_{i-1} - dt| <= 1e-3 dt with dt the mean spacing) and agree
// with "dt=" when both are given. Every field must be a finite number.
// Errors: manip::InputError "FILE:LINE: reason" (exit code 4).
#include <string>
#include <vector>

#include "manip/diagnosis/dataset.hpp"

namespace manip::diagnosis {

struct SingleJointRecord {
  std::string source;  // file name as given
  double dt_s = 0.0;
  std::vector<double> pos_rad;
  std::vector<double> torque_nm;
  // How the columns were chosen when not by the default two/three-column
  // layout (a "channels=" comment or a header line with extra columns), e.g.
  // "columns by name: position 'pos1' (1), torque 'tq1' (2); ignored 'emg' (3)".
  std::string columns_note;
};

[[nodiscard]] SingleJointRecord read_single_joint_csv(const std::string& path);

// Smoothing/differentiation of a single-joint record: order-5 Savitzky-Golay
// (the estimator's order, docs/estimator.md), window nearest to the cut-off
// below; the same smoother is applied to the torque and to every regressor
// column, so linear terms commute exactly with the filter.
struct SingleJointOptions {
  // 40 Hz: the ankle's response to position perturbations lies below ~50 Hz
  // (Kearney, Stein & Parameswaran 1997 and Mirbagheri et al. 2000 analyse
  // it after decimation to 100 Hz, i.e. a 0-50 Hz band); the cut-off is
  // capped at fs / 8 so the window keeps >= ~20 samples at low sampling rates.
  double cutoff_hz = 40.0;
  int polyorder = 5;
  // Torque sign: +1 or -1 as given; 0 = decide from the data: the elastic
  // term must oppose displacement (K > 0 in torque = I a + B v + K x + c), so
  // a negative baseline K means the record stores the reaction torque on the
  // actuator; it is then flipped and the report says so.
  int torque_sign = 0;
  // Inertia known from elsewhere (kg m^2): when set, the baseline fixes it
  // and the "wrong inertia" mechanism becomes testable.
  double fixed_inertia_kgm2 = 0.0;
  bool inertia_fixed = false;
};

struct SingleJointPrepared {
  Dataset data;
  int window = 0;          // Savitzky-Golay window used (samples)
  double cutoff_hz = 0.0;  // its -3 dB point
  int torque_sign = 1;     // applied to the recorded torque
  bool sign_flipped_automatically = false;
};

// Builds the engine's dataset: one segment, base columns [acc, vel, pos, 1]
// (or [vel, pos, 1] with the inertia term moved to the target when fixed).
[[nodiscard]] SingleJointPrepared prepare_single_joint(const SingleJointRecord& rec,
                                                       const SingleJointOptions& opt = {});

// Physical checks of the baseline fit, one line each (empty: none fails).
// A passive joint has B > 0 and I > 0. A first-order lag T of the torque
// channel behind the position channel turns tau = (I s^2 + B s + K) x into
// tau / (1 + T s) = K x + (B - T K) s x + (I - T B + T^2 K) s^2 x + O(s^3):
// K is kept, B and I move along the data's own directions (velocity,
// acceleration), so no column added to the baseline tells the lag from them
// (the output-error fit of torque_lag.hpp does, from the O(s^3) part;
// docs/diagnosis.md, "Torque-channel lag"). What the baseline alone can say
// is the least lag that explains a negative B: T >= -B / K.
struct PhysicalCheck {
  std::string what;        // "B < 0"
  std::string text;        // the one-line finding
  double least_lag_s = 0;  // B < 0: -B / K (the least torque-channel lag that explains it); else 0
};
struct Diagnosis;  // engine.hpp
[[nodiscard]] std::vector<PhysicalCheck> single_joint_physical_checks(const Diagnosis& d);

}  // namespace manip::diagnosis
