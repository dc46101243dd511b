#pragma once
// Umbrella header for manip::dsp, the scipy-compatible signal-processing core.
#include "manip/dsp/butterworth.hpp"
#include "manip/dsp/integrate.hpp"
#include "manip/dsp/savgol.hpp"
#include "manip/dsp/sos.hpp"
#include "manip/dsp/sosfilt.hpp"
#include "manip/dsp/welch.hpp"
