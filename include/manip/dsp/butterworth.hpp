#pragma once
// Digital Butterworth design, bit-for-bit the algorithm of
// scipy.signal.butter(order, fc_hz, btype, fs=fs_hz, output='sos') (scipy 1.10):
// analog prototype (buttap) -> tan prewarp of the cut-off -> lp2lp/lp2hp ->
// bilinear transform (fs = 2 after normalisation) -> zpk2sos with scipy's
// default 'nearest' pairing for digital filters (poles closest to the unit
// circle end up in the LAST section, an odd order gets a first-order section
// padded with a zero pole/zero, the overall gain is folded into section 1).
// The paper's high pass is butter(5, 1 Hz, highpass, fs = 4 kHz).
#include <vector>

#include "manip/dsp/sos.hpp"

namespace manip::dsp {

enum class BandType { lowpass, highpass };

// Throws std::invalid_argument unless order >= 1, fs_hz > 0 and 0 < fc_hz < fs_hz / 2
// (scipy: "Digital filter critical frequencies must be 0 < Wn < fs/2").
// Returns (order + 1) / 2 sections, every a0 == 1.
[[nodiscard]] std::vector<Sos> butter(int order, double fc_hz, double fs_hz, BandType type);

}  // namespace manip::dsp
