"""Text, CSV and JSON tables.

Text tables never fuse: every column is as wide as its widest cell plus a
two-space gutter, and numbers switch to scientific notation outside
[1e-3, 1e6). Matrix elements are labelled (D11 ... K22, with units), the
default method and methods known to be biased are marked.
"""
from __future__ import annotations

import csv
import io
import json
import math
from typing import Dict, Iterable, List, Optional, Sequence

import numpy as np

from . import analysis as A
from .io import BIASED_METHODS, DEFAULT_METHOD, SessionResult, Summary

UNIT = {"D": "N s/m", "K": "N/m"}
UNIT_SUFFIX = {"D": "Nspm", "K": "Npm"}
GUTTER = "  "


def fmt_num(x, sig: int = 4) -> str:
    """Round to ``sig`` significant digits; fixed notation in [1e-3, 1e6), else scientific."""
    if x is None:
        return "n/a"
    x = float(x)
    if not math.isfinite(x):
        return "n/a" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if x == 0:
        return "0"
    ax = abs(x)
    if 1e-3 <= ax < 1e6:
        dec = max(0, sig - 1 - int(math.floor(math.log10(ax))))
        return "%.*f" % (dec, x)
    return "%.*e" % (sig - 1, x)


def fmt_interval(lo, hi, sig: int = 4) -> str:
    return "[%s, %s]" % (fmt_num(lo, sig), fmt_num(hi, sig))


def text_table(headers: Sequence[str], rows: Iterable[Sequence[str]], right: Optional[Sequence[bool]] = None) -> str:
    """Columns sized from the data; numbers right-aligned, text left-aligned."""
    rows = [[str(c) for c in r] for r in rows]
    headers = [str(h) for h in headers]
    n = len(headers)
    for r in rows:
        if len(r) != n:
            raise ValueError("row has %d cells, header %d" % (len(r), n))
    w = [max([len(headers[i])] + [len(r[i]) for r in rows]) for i in range(n)]
    if right is None:
        right = [i > 0 for i in range(n)]

    def line(cells):
        return GUTTER.join(c.rjust(w[i]) if right[i] else c.ljust(w[i]) for i, c in enumerate(cells)).rstrip()

    out = [line(headers), line(["-" * x for x in w])]
    out += [line(r) for r in rows]
    return "\n".join(out) + "\n"


def method_marks(method: str, default_method: str = DEFAULT_METHOD) -> str:
    m = []
    if method == default_method:
        m.append("default, recommended")
    if method in BIASED_METHODS:
        m.append("BIASED")
    return "; ".join(m)


def legend_lines(methods: Iterable[str], default_method: str = DEFAULT_METHOD) -> str:
    out = []
    if default_method in methods:
        out.append("default, recommended: %s (docs/estimator.md, docs/accuracy-study.md)" % default_method)
    for m in methods:
        if m in BIASED_METHODS:
            out.append("BIASED: %s is %s; do not report it" % (m, BIASED_METHODS[m]))
    return "".join("  note: %s\n" % x for x in out)


# --------------------------------------------------------------------------- session Table 1
def summary_cells(s: Summary, sig: int = 4) -> Dict[str, str]:
    """'D11'.. -> 'estimate [lo, hi]' (or 'estimate (spread)' without an interval)."""
    out = {}
    for name in A.ELEMENT_NAMES:
        v = A.element_value(s, name)
        lo, hi = A.element_value(s, name, "lo"), A.element_value(s, name, "hi")
        if math.isfinite(lo) and math.isfinite(hi):
            out[name] = "%s %s" % (fmt_num(v, sig), fmt_interval(lo, hi, sig))
        else:
            out[name] = "%s (%s)" % (fmt_num(v, sig), fmt_num(A.element_value(s, name, "spread"), sig))
    return out


def flag_text(s: Summary) -> str:
    if s.identifiable is False:
        return "NOT IDENTIFIABLE" + (": " + s.flag if s.flag else "")
    return s.flag or ""


def session_table_text(r: SessionResult, default_method: str = DEFAULT_METHOD, sig: int = 4) -> str:
    """Table-1 summary of one session: one row per method, every element labelled with
    its unit, estimate and 95 % interval, flags, default/biased marks."""
    headers = ["method", "kind", "n"] + ["%s [%s]" % (n, UNIT[n[0]]) for n in A.ELEMENT_NAMES] + ["flags", "notes"]
    rows = []
    methods = r.methods()
    for m in methods:
        s = r.summary(m, "session")
        if s is None:
            continue
        c = summary_cells(s, sig)
        rows.append([m, s.kind, "" if s.n_trials is None else str(s.n_trials)] + [c[n] for n in A.ELEMENT_NAMES]
                    + [flag_text(s), method_marks(m, default_method)])
    right = [False, False, True] + [True] * 8 + [False, False]
    txt = "Session %s (%s): estimate [95 %% interval]\n" % (r.participant, r.log)
    txt += text_table(headers, rows, right)
    txt += legend_lines(methods, default_method)
    if r.truth:
        Dt, Kt = r.truth_mats()
        txt += "  truth (%s): " % r.truth.get("model", "simulated")
        txt += "  ".join("%s = %s %s" % (n, fmt_num((Dt if n[0] == "D" else Kt).ravel()[i % 4], sig), UNIT[n[0]])
                         for i, n in enumerate(A.ELEMENT_NAMES)) + "\n"
    return txt


def truth_error_text(r: SessionResult, sig: int = 3) -> str:
    """'error vs truth' with every element labelled, per method (relative, %)."""
    Dt, Kt = r.truth_mats()
    if Dt is None:
        return ""
    headers = ["method"] + ["%s err [%%]" % n for n in A.ELEMENT_NAMES]
    rows = []
    for m in r.methods():
        s = r.summary(m, "session")
        if s is None or s.D is None:
            continue
        cells = []
        for n in A.ELEMENT_NAMES:
            t = (Dt if n[0] == "D" else Kt).ravel()[A.ELEMENTS.index(n[1:])]
            v = A.element_value(s, n)
            cells.append(fmt_num(100 * (v - t) / t, sig) if t else "n/a")
        rows.append([m] + cells)
    return "Error vs truth (estimate - truth) / truth:\n" + text_table(headers, rows)


def directional_rows(r: SessionResult, method: str) -> List[dict]:
    """Per angle: u^T D u and u^T K u with intervals (one dict per angle)."""
    by = {}
    for d in A.directional_table(r, method):
        e = by.setdefault(d.angle_deg, {"angle_deg": d.angle_deg, "method": method, "n_trials": d.n_trials,
                                        "identifiable": d.identifiable, "flag_reason": d.flag, "interval": d.interval})
        u = UNIT_SUFFIX[d.which]
        e["u%su_%s" % (d.which, u)] = d.value
        e["u%su_ci95_lo_%s" % (d.which, u)] = d.lo
        e["u%su_ci95_hi_%s" % (d.which, u)] = d.hi
    return [by[k] for k in sorted(by)]


DIRECTIONAL_COLUMNS = ["method", "angle_deg", "n_trials", "uDu_Nspm", "uDu_ci95_lo_Nspm", "uDu_ci95_hi_Nspm",
                       "uKu_Npm", "uKu_ci95_lo_Npm", "uKu_ci95_hi_Npm", "interval", "identifiable", "flag_reason"]


def directional_text(r: SessionResult, method: str) -> str:
    rows = directional_rows(r, method)
    if not rows:
        return ""
    headers = ["angle [deg]", "uᵀDu [N s/m]", "95 % interval", "uᵀKu [N/m]", "95 % interval", "n", "fit flag"]
    body = [["%g" % x["angle_deg"], fmt_num(x.get("uDu_Nspm")),
             fmt_interval(x.get("uDu_ci95_lo_Nspm"), x.get("uDu_ci95_hi_Nspm")), fmt_num(x.get("uKu_Npm")),
             fmt_interval(x.get("uKu_ci95_lo_Npm"), x.get("uKu_ci95_hi_Npm")),
             "" if x["n_trials"] is None else str(x["n_trials"]),
             ("full 2x2 not identifiable" if x["identifiable"] is False else "")] for x in rows]
    return ("Directional impedance along the push u = (cos φ, sin φ), %s (intervals: %s):\n"
            % (method, rows[0]["interval"])) + text_table(headers, body)


def _csv_value(v):
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(v)
    return v


def write_csv(path_or_buf, columns: Sequence[str], rows: Iterable[dict]) -> None:
    own = isinstance(path_or_buf, str)
    f = open(path_or_buf, "w", newline="", encoding="utf-8") if own else path_or_buf
    try:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(columns)
        for r in rows:
            w.writerow([_csv_value(r.get(c)) for c in columns])
    finally:
        if own:
            f.close()


# --------------------------------------------------------------------------- group Table 1
GROUP_COLUMNS = ["level", "participant_id", "log", "method", "is_default", "is_biased", "parameter", "quantity",
                 "row", "col", "unit", "statistic", "value_si", "ci95_lo_si", "ci95_hi_si", "n_participants",
                 "identifiable", "flag_reason"]


def group_rows(g: A.GroupTable, default_method: str = DEFAULT_METHOD) -> List[dict]:
    """Tidy long form: one row per (participant or group statistic, element)."""
    out = []
    base = dict(method=g.method, is_default=g.method == default_method, is_biased=g.method in BIASED_METHODS)
    for name in A.ELEMENT_NAMES:
        common = dict(base, parameter=name, quantity="damping" if name[0] == "D" else "stiffness",
                      row=int(name[1]), col=int(name[2]), unit=UNIT[name[0]])
        for r in g.rows:
            s = r.summary
            out.append(dict(common, level="participant", participant_id=r.participant, log=r.log,
                            statistic="estimate", value_si=A.element_value(s, name),
                            ci95_lo_si=A.element_value(s, name, "lo"), ci95_hi_si=A.element_value(s, name, "hi"),
                            n_participants=1, identifiable=s.identifiable, flag_reason=s.flag))
        for stat, v in (("mean", g.mean[name]), ("std", g.std[name])):
            out.append(dict(common, level="group", participant_id="", log="", statistic=stat, value_si=v,
                            n_participants=g.n))
    return out


def group_text(g: A.GroupTable, default_method: str = DEFAULT_METHOD, sig: int = 4) -> str:
    headers = ["participant"] + ["%s [%s]" % (n, UNIT[n[0]]) for n in A.ELEMENT_NAMES] + ["flags"]
    rows = [[r.participant] + [summary_cells(r.summary, sig)[n] for n in A.ELEMENT_NAMES] + [flag_text(r.summary)]
            for r in g.rows]
    rows.append(["mean (std), n = %d" % g.n] + ["%s (%s)" % (fmt_num(g.mean[n], sig), fmt_num(g.std[n], sig))
                                               for n in A.ELEMENT_NAMES] + [""])
    marks = method_marks(g.method, default_method)
    txt = "Group table (paper Table 1 layout), method %s%s: participants' estimate [95 %% interval]; " \
          "last row mean (std) over participants (std with n - 1)\n" % (g.method, " [%s]" % marks if marks else "")
    txt += text_table(headers, rows, [False] + [True] * 8 + [False])
    txt += legend_lines([g.method], default_method)
    return txt


def group_json(g: A.GroupTable, default_method: str = DEFAULT_METHOD) -> dict:
    def clean(v):
        return None if v is None or (isinstance(v, float) and not math.isfinite(v)) else v
    return {
        "method": g.method, "is_default": g.method == default_method, "biased": BIASED_METHODS.get(g.method),
        "n_participants": g.n, "std_ddof": 1,
        "elements": {n: {"unit": UNIT[n[0]], "mean": clean(g.mean[n]), "std": clean(g.std[n])} for n in A.ELEMENT_NAMES},
        "participants": [{"participant_id": r.participant, "log": r.log, "identifiable": r.summary.identifiable,
                          "flag_reason": r.summary.flag,
                          "elements": {n: {"unit": UNIT[n[0]], "estimate": clean(A.element_value(r.summary, n)),
                                           "ci95_lo": clean(A.element_value(r.summary, n, "lo")),
                                           "ci95_hi": clean(A.element_value(r.summary, n, "hi"))}
                                       for n in A.ELEMENT_NAMES}} for r in g.rows],
    }


def main(argv=None) -> int:
    """python3 -m manipplot.tables RESULTS.json [--method M] [--directional-csv DIR]: the Table-1 summary,
    errors vs truth and directional impedance per angle of every session, as text."""
    import argparse
    import os
    import sys
    from .io import load_results
    ap = argparse.ArgumentParser(prog="python3 -m manipplot.tables", description=main.__doc__)
    ap.add_argument("results")
    ap.add_argument("--method", action="append", help="methods for the per-angle table (default: the default method)")
    ap.add_argument("--directional-csv", help="write directional_<method>.csv per session into this directory")
    a = ap.parse_args(argv)
    try:
        res = load_results(a.results)
    except (OSError, ValueError) as e:
        print("manipplot.tables: %s" % e, file=sys.stderr)
        return 2
    for s in res.sessions:
        print(session_table_text(s, res.default_method))
        err = truth_error_text(s)
        if err:
            print(err)
        for m in a.method or [res.default_method]:
            txt = directional_text(s, m)
            if txt:
                print(txt)
            if a.directional_csv:
                os.makedirs(a.directional_csv, exist_ok=True)
                stem = os.path.splitext(os.path.basename(s.log))[0] or "session"
                write_csv(os.path.join(a.directional_csv, "%s_directional_%s.csv" % (stem, m)), DIRECTIONAL_COLUMNS,
                          directional_rows(s, m))
    return 0


if __name__ == "__main__":
    import sys
    sys.exit(main())
