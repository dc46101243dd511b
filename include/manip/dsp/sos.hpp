#pragma once
// Second-order sections, scipy's `sos` row layout [b0, b1, b2, a0, a1, a2].
//
// The estimator's 1 Hz high pass at 4 kHz (paper, "Isolation of the feedback
// behavior") has poles within 2e-3 of z = 1; its transfer-function [b, a] form
// loses most of its accuracy (platform facts: |H(0.5 Hz)| 0.076 instead of
// 0.031), so every IIR filter in manip::dsp is kept and applied as cascaded
// second-order sections.
namespace manip::dsp {

struct Sos {
  double b0, b1, b2, a0, a1, a2;
};

}  // namespace manip::dsp
