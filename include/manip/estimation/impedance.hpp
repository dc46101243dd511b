#pragma once
// The impedance fits (paper §3.3 and the project's extensions), one header
// each: the result type (estimate.hpp), the paper's equation error
// (equation_error.hpp), output error (output_error.hpp), the statistics they
// share (uncertainty.hpp). The default method, prediction error, is pem.hpp;
// the methods built on these fits are in methods/ (docs/estimator.md).
#include "manip/estimation/equation_error.hpp"
#include "manip/estimation/estimate.hpp"
#include "manip/estimation/output_error.hpp"
#include "manip/estimation/uncertainty.hpp"
