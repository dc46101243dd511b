#pragma once
// Figures and the HTML session report are drawn by the Python package
// python/manipplot (matplotlib); the C++ tools only write the data files
// (results JSON, exported signals, validation JSON) and call the command
// lines docs/report.md specifies. No plotting code in C++.
//
// Interpreter: $MANIP_PYTHON, else <source>/.venv/bin/python, else python3.
// Environment: PYTHONPATH=<source>/python:<build>/python, MPLBACKEND=Agg.
// <source>/<build> come from $MANIP_SOURCE_DIR/$MANIP_BUILD_DIR, else from
// the running executable (<build>/apps/<tool>, <build>/CMakeCache.txt).
#include <string>
#include <vector>

#include "manip/estimation/session_estimator.hpp"

namespace manip::estimation {

struct RenderInputs {
  std::string results_json;     // estimate_impedance --json layout (required)
  std::string signals_dir;      // export_signals() output (per log: <dir> or <dir>/<stem>/), optional
  std::string log;              // the LCM log, or a directory of logs, optional (Fig. 3/4 from raw data)
  std::string validation_json;  // manip_sim --validate's validation.json, optional (Fig. 4)
};

// What manipplot reported: 0 everything drawn, 1 written but something could
// not be drawn (named in `notes`, pass on as a warning).
struct RenderResult {
  int manipplot_exit{0};
  std::vector<std::string> notes;  // manipplot's stderr lines
};

// `python -m manipplot.plots ... -o <tmp> --format png,pdf,svg` into a fresh
// temporary directory next to out_dir; on success its files are moved into
// out_dir (created if needed; an existing file there is refused unless
// force, before anything is moved). Throws manip::OutputError (exit 6) with
// one line when Python, matplotlib or manipplot is missing, manipplot refuses
// its input (its exit 2), or out_dir cannot be written; nothing is left behind.
// manip_sim --validate DIR: render_plots({DIR/estimate.json, DIR/signals,
// OUT.lcm, DIR/validation.json}, DIR, force) (docs/report.md).
RenderResult render_plots(const RenderInputs& in, const std::string& out_dir, bool force);

// The mechanism of render_plots for any manipplot module (diagnose_model:
// manipplot.diagnosis): `python -m <module> ARGS... -o <tmp> --format
// <formats>` into a fresh temporary directory next to out_dir, its files
// moved into out_dir as above; the same errors (exit 6, "--plots out_dir").
RenderResult render_module_into(const std::string& module, const std::vector<std::string>& args, const std::string& formats,
                                const std::string& out_dir, bool force);

// `python -m manipplot.report ... -o FILE.html` through AtomicOutput.
RenderResult render_report(const std::vector<std::string>& results_json, const RenderInputs& extra,
                           const std::string& html_path, bool force);

// One line naming what is missing if manipplot cannot run here (interpreter,
// matplotlib, numpy, the package), else empty. For checks before any work.
std::string python_unavailable_reason();

// The interpreter render_* would use (for messages and tests).
std::string python_interpreter();

// For a caller holding only a Report (manip_sim --validate today): writes
// its JSON and signals into a temporary directory (removed afterwards) and
// calls render_plots into dir, with dir/validation.json if present (Fig. 4).
// An existing file in dir is refused unless force. Throws manip::OutputError.
RenderResult write_plots(const Report& r, const std::string& log, const std::string& dir, bool force);
// Former entry, kept so manip_sim builds until it calls render_plots: no
// log (Fig. 3 from the JSON's PSD arrays), and its figures in dir are
// redrawn (force), as the SVG writer did.
void write_plots(const Report& r, const std::string& dir);

}  // namespace manip::estimation
