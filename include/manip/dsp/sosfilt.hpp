#pragma once
// Applying second-order sections with scipy.signal semantics (scipy 1.10):
// sosfilt (direct form II transposed, one section after the other per sample),
// sosfilt_zi (steady-state initial conditions for a unit step) and
// sosfiltfilt with scipy's DEFAULT padding (padtype='odd', padlen=None).
//
// The paper applies its high pass "bi-directionally to guarantee zero phase
// distortion"; with a 1 Hz cut-off the filter's time constants are of the
// order of a 3 s record, so the padding convention visibly changes the result
// (platform facts: scipy vs MATLAB differ by 0.6-4.5% mid-record). We follow
// scipy exactly: odd extension, padlen from the section count, initial state
// sosfilt_zi scaled by the first sample of the extended signal (forward) and
// by the last forward output (backward).
#include <span>
#include <vector>

#include "manip/dsp/sos.hpp"

namespace manip::dsp {

// scipy.signal.sosfilt_zi: steady-state state of each section for a unit step
// at the cascade input, layout [section0.z0, section0.z1, section1.z0, ...].
// Throws std::invalid_argument for an empty cascade or a section with a pole at
// z = 1 (singular steady state; numpy raises LinAlgError there).
[[nodiscard]] std::vector<double> sosfilt_zi(std::span<const Sos> sos);

// scipy.signal.sosfilt(sos, x, zi=zi). y.size() must equal x.size(); y may be
// the same memory as x (in-place) but must not partially overlap it.
// zi_inout: empty -> zero initial state; otherwise 2 * sos.size() values in
// sosfilt_zi's layout, overwritten with the final state (scipy's `zf`).
// Throws std::invalid_argument for an empty cascade, a0 != 1 (scipy requires
// normalised sections), or mismatched sizes. Never allocates. Performs scipy's
// operations in scipy's order: given the same sections the output is
// bit-identical to scipy's (tested).
void sosfilt(std::span<const Sos> sos, std::span<const double> x, std::span<double> y,
             std::span<double> zi_inout = {});

// scipy's default sosfiltfilt edge length:
// 3 * (2 * n_sections + 1 - min(#sections with b2 == 0, #sections with a2 == 0)).
// 18 for butter(5, ...) (three sections, one of them first order). Note the
// min of two counts (scipy's code), not "sections with b2 == a2 == 0"; the two
// agree for Butterworth designs.
[[nodiscard]] int sosfiltfilt_padlen(std::span<const Sos> sos);

// scipy.signal.sosfiltfilt(sos, x) with default padtype='odd', padlen=None.
// Throws std::invalid_argument (message names both lengths) when
// x.size() <= sosfiltfilt_padlen(sos), for mismatched sizes and for x, y
// partially overlapping (y == x, in place, is fine).
// Scratch: the padded signal and the initial states live in a thread_local
// buffer that only grows, so repeated calls with signals no longer than the
// longest seen so far do not allocate; each thread has its own buffer, so the
// function is thread-safe but keeps (len + 2 * padlen + 4 * n_sections) doubles
// per calling thread alive until the thread exits.
void sosfiltfilt(std::span<const Sos> sos, std::span<const double> x, std::span<double> y);

}  // namespace manip::dsp
