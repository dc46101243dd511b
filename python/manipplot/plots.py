"""Write the session figures (PNG + PDF by default) into a directory.

    python3 -m manipplot.plots RESULTS.json [--signals DIR] [--log LOG] [--validation validation.json]
                               [--method M ...] [--all-trials] [--format png,pdf,svg] [--dpi 200] -o DIR

Files: fig3_psd_jerk_x2, fig4_nrmse, fig5_trial_<k>, directional_<method>,
table1_<method> (each .png/.pdf/...), directional_<method>.csv (per angle,
tidy, units in column names). With several sessions in RESULTS.json each goes
to DIR/<log stem>/. Exit codes: 0 ok, 2 bad command line or unreadable
input, 1 some figures could not be drawn (named on stderr).
"""
from __future__ import annotations

import argparse
import os
import sys

from . import build as B
from . import tables as T
from .io import load_results


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m manipplot.plots", description=__doc__.split("\n\n")[0])
    ap.add_argument("results", help="estimate_impedance --json output")
    ap.add_argument("--signals", help="estimate_impedance --export-signals directory")
    ap.add_argument("--log", help="the session's LCM log (or a directory of logs)")
    ap.add_argument("--validation", help="manip_sim --validate DIR/validation.json (Fig. 4 without the log)")
    ap.add_argument("--method", action="append", help="methods for per-angle figures (default: all in the JSON)")
    ap.add_argument("--all-trials", action="store_true", help="Fig. 5 for every exported trial (default: first)")
    B.F.add_output_options(ap, "PNG resolution (default 200: 700 px at 3.5 in)")
    a = ap.parse_args(argv)
    fmts = B.F.output_formats(ap, a)
    try:
        res = load_results(a.results)
        inputs = B.resolve_inputs(res, a.signals, a.log, a.validation)
    except (OSError, ValueError, KeyError) as e:
        print("manipplot.plots: %s" % e, file=sys.stderr)
        return 2
    rc = 0
    for inp in inputs:
        d = a.out if len(inputs) == 1 else os.path.join(a.out, os.path.splitext(os.path.basename(inp.session.log))[0])
        os.makedirs(d, exist_ok=True)
        figs = B.session_figures(inp, a.method, a.all_trials, res.default_method)
        for name, fig in figs.items():
            for p in B.F.save(fig, os.path.join(d, name), fmts, a.dpi):
                print(p)
        for m in a.method or inp.session.methods():
            rows = T.directional_rows(inp.session, m)
            if rows:
                p = os.path.join(d, "directional_%s.csv" % m)
                T.write_csv(p, T.DIRECTIONAL_COLUMNS, rows)
                print(p)
        for n in inp.notes:
            print("manipplot.plots: %s: %s" % (inp.session.log, n), file=sys.stderr)
            if "not drawn" in n:
                rc = 1
    return rc


if __name__ == "__main__":
    sys.exit(main())
