"""Self-contained HTML session (and group) report.

    python3 -m manipplot.report RESULTS.json [RESULTS.json ...] [--signals DIR] [--log LOG]
                                [--validation validation.json] [--all-trials] -o report.html

One page, no external resources (figures inlined as base64 PNG): per session
the Table-1 summary with 95 % intervals and flags (default method marked,
biased methods marked), errors vs truth for simulated logs, directional
impedance per angle, the figures, the settings used, warnings, excluded
trials and why. With several sessions (several logs in one JSON, or several
JSONs) a group table (mean (std) over participants) comes first.
Exit codes: 0 written; 1 written but some figures could not be drawn (listed
in the page and on stderr); 2 bad command line or unreadable input.
"""
from __future__ import annotations

import argparse
import base64
import datetime
import html
import io
import json
import math
import os
import sys
from typing import List, Optional

from . import __version__
from . import analysis as A
from . import build as B
from . import figures as F
from . import tables as T
from .io import BIASED_METHODS, Results, SessionResult, load_results

CSS = """
body{font-family:'DejaVu Sans',Arial,sans-serif;font-size:14px;margin:24px;max-width:1150px;color:#111;background:#fff}
h1{font-size:22px} h2{font-size:18px;border-bottom:1px solid #999;margin-top:32px} h3{font-size:15px}
table{border-collapse:collapse;margin:8px 0 16px 0} th,td{border:1px solid #bbb;padding:3px 6px;text-align:right;white-space:nowrap}
th{background:#eee} td.l,th.l{text-align:left}
tr.default td{background:#eef7ee;font-weight:bold} tr.biased td{background:#fbeaea;color:#700}
span.flag{color:#b00;font-weight:bold} span.small{font-size:11px} span.mark{font-size:12px;padding:1px 4px;border-radius:3px;margin-left:4px}
span.def{background:#2a7a2a;color:#fff} span.bias{background:#a00;color:#fff}
figure{display:inline-block;margin:8px 12px 8px 0;vertical-align:top} figure img{width:480px;height:auto;border:1px solid #ddd}
figcaption{font-size:12px;max-width:480px;color:#333} span.ci{font-size:12px;color:#444}
td.wrap{white-space:normal;overflow-wrap:anywhere;max-width:320px} td.kind{white-space:normal;max-width:260px;min-width:110px} h4{font-size:14px;margin:10px 0 0 0} .note{color:#555;font-size:12px} ul.warn li{color:#840}
"""

CAPTIONS = {
    "fig3_psd_jerk_x2": "Fig. 3: mean PSD of the principal-axis (x2) jerk, unperturbed vs perturbed trials, in dB "
                        "relative to the unperturbed peak (value in the title); dotted: unperturbed + threshold, "
                        "circle: auto cut-off, dash-dot: cut-off used by the high-pass filter.",
    "fig4_nrmse": "Fig. 4: NRMSE(Δt) of the isolated variational signals against the simulator's twin truth, "
                  "x1 solid, x2 dashed, bands ±1 std over trials; grey dash-dot: the paper's bound.",
    "fig5": "Fig. 5: variational dynamics of one perturbed trial: perturbation force, Δu_ext (eq. 21), Δẍ, Δẋ, Δx; "
            "dotted: twin truth (simulated logs).",
    "directional": "Directional impedance uᵀDu and uᵀKu along the push u = (cos φ, sin φ) per angle, with 95 % "
                   "intervals (hollow: the per-angle 2×2 fit is flagged; its directional value is still determined); "
                   "green: the session's full 2×2 estimate; dotted: truth (simulated logs).",
    "table1": "Table 1 layout: estimate [95 % interval] of each element.",
}


def _e(x) -> str:
    return html.escape(str(x), quote=True)


def fig_to_img(fig, name: str, alt: str) -> str:
    buf = io.BytesIO()
    import matplotlib
    with matplotlib.rc_context(F.RC):
        fig.savefig(buf, format="png", dpi=150, bbox_inches="tight", pad_inches=0.02)
    b64 = base64.b64encode(buf.getvalue()).decode("ascii")
    return '<img data-figure="%s" alt="%s" src="data:image/png;base64,%s">' % (_e(name), _e(alt), b64)


def caption_of(name: str) -> str:
    for k, v in CAPTIONS.items():
        if name.startswith(k):
            return v
    return ""


def html_table(headers: List[str], rows: List[List[str]], row_classes: Optional[List[str]] = None,
               left_cols=(0,), cls: str = "", col_classes: Optional[dict] = None) -> str:
    col_classes = col_classes or {}

    def k(i):
        return " ".join(x for x in ("l" if i in left_cols else "", col_classes.get(i, "")) if x)
    out = ['<table class="%s">' % _e(cls), "<tr>"]
    out += ['<th class="%s">%s</th>' % (k(i), h) for i, h in enumerate(headers)]
    out.append("</tr>")
    for j, r in enumerate(rows):
        out.append('<tr class="%s">' % _e(row_classes[j] if row_classes else ""))
        out += ['<td class="%s">%s</td>' % (k(i), c) for i, c in enumerate(r)]
        out.append("</tr>")
    out.append("</table>")
    return "\n".join(out)


def marks_html(method: str, default_method: str) -> str:
    out = ""
    if method == default_method:
        out += '<span class="mark def">default, recommended</span>'
    if method in BIASED_METHODS:
        out += '<span class="mark bias" title="%s">BIASED</span>' % _e(BIASED_METHODS[method])
    return out


def _cell2(text: str) -> str:
    """'estimate [lo, hi]' -> estimate, interval on a second line (keeps wide tables on the page)."""
    est, sep, rest = text.partition(" ")
    return _e(est) + ("<br><span class='ci'>%s</span>" % _e(rest) if sep else "")


def session_table_html(s: SessionResult, default_method: str) -> str:
    """Table-1 summary as two tables (damping, stiffness) so that wide numbers stay on the page."""
    methods = [m for m in s.methods() if s.summary(m, "session") is not None]
    Dt, Kt = s.truth_mats()
    out = []
    for which, title in (("D", "Damping D [N s/m]"), ("K", "Stiffness K [N/m]")):
        names = [n for n in A.ELEMENT_NAMES if n[0] == which]
        headers = ["method", "kind", "n"] + ["%s [%s]" % (n, T.UNIT[which]) for n in names] + ["flags"]
        rows, cls = [], []
        for m in methods:
            summ = s.summary(m, "session")
            c = T.summary_cells(summ)
            flag = T.flag_text(summ)
            rows.append([_e(m) + marks_html(m, default_method), _e(summ.kind), _e(summ.n_trials or "")]
                        + [_cell2(c[n]) for n in names] + ['<span class="flag">%s</span>' % _e(flag) if flag else ""])
            cls.append("default" if m == default_method else ("biased" if m in BIASED_METHODS else ""))
        M = Dt if which == "D" else Kt
        if M is not None:
            rows.append(["truth", _e(s.truth.get("model", "")), ""]
                        + [_e(T.fmt_num(M.ravel()[A.ELEMENTS.index(n[1:])])) for n in names] + [""])
            cls.append("truth")
        out.append("<h4>%s</h4>" % _e(title))
        out.append(html_table(headers, rows, cls, left_cols=(0, 1, 7), cls="table1",
                              col_classes={1: "kind", 7: "kind"}))
    notes = "".join("<li>%s</li>" % _e(x) for x in T.legend_lines(methods, default_method).replace("  note: ", "")
                    .strip().splitlines() if x)
    return "\n".join(out) + ("<ul>%s</ul>" % notes if notes else "")


def directional_html(s: SessionResult, method: str) -> str:
    rows = T.directional_rows(s, method)
    if not rows:
        return ""
    body = [[_e("%g" % x["angle_deg"]), _e(T.fmt_num(x.get("uDu_Nspm"))),
             _e(T.fmt_interval(x.get("uDu_ci95_lo_Nspm"), x.get("uDu_ci95_hi_Nspm"))), _e(T.fmt_num(x.get("uKu_Npm"))),
             _e(T.fmt_interval(x.get("uKu_ci95_lo_Npm"), x.get("uKu_ci95_hi_Npm"))), _e(x.get("n_trials") or ""),
             _e("full 2×2 not identifiable (expected for one direction)" if x["identifiable"] is False else "")]
            for x in rows]
    return ("<h3>Directional impedance per angle (%s)</h3><p class='note'>Intervals: %s. A single push direction "
            "determines the impedance along the push, not the full 2×2 matrices; those are reported for the pooled "
            "session only.</p>" % (_e(method), _e(rows[0]["interval"]))
            + html_table(["angle [deg]", "uᵀDu [N s/m]", "95 % interval", "uᵀKu [N/m]", "95 % interval", "n trials",
                          "per-angle 2×2 fit"], body, left_cols=(6,), cls="directional"))


def group_html(sessions: List[SessionResult], default_method: str) -> str:
    try:
        A.check_same_configuration(sessions)
    except A.GroupError as e:
        return "<h2>Group table</h2><p class='flag'>Not pooled: %s</p>" % _e(e)
    out = ["<h2>Group table (paper Table 1 layout)</h2>"]
    methods = [m for m in sessions[0].methods() if all(s.summary(m, "session") is not None for s in sessions)]
    for m in methods:
        g = A.group_table(sessions, m)
        headers = ["participant (flags)"] + ["%s [%s]" % (n, T.UNIT[n[0]]) for n in A.ELEMENT_NAMES]

        def who(r):
            f = T.flag_text(r.summary)
            return _e(r.participant) + ("<br><span class='flag small'>%s</span>" % _e(f) if f else "")
        rows = [[who(r)] + [_cell2(T.summary_cells(r.summary)[n]) for n in A.ELEMENT_NAMES] for r in g.rows]
        rows.append(["<b>mean (std), n = %d</b>" % g.n] + ["<b>%s (%s)</b>" % (_e(T.fmt_num(g.mean[n])),
                                                                               _e(T.fmt_num(g.std[n])))
                                                          for n in A.ELEMENT_NAMES])
        out.append("<h3>%s%s</h3>" % (_e(m), marks_html(m, default_method)))
        out.append(html_table(headers, rows, left_cols=(0,), cls="group", col_classes={0: "kind"}))
    return "\n".join(out)


def build_report(res_list: List[Results], signals: Optional[str], log: Optional[str], validation: Optional[str],
                 all_trials: bool = False):
    default = res_list[0].default_method
    parts = ["<!DOCTYPE html><html><head><meta charset='utf-8'><title>manip session report</title>",
             "<style>%s</style></head><body>" % CSS, "<h1>manip session report</h1>",
             "<p class='note'>%s; manipplot %s; manip %s; generated %s UTC</p>" % (
                 ", ".join(_e(r.path) for r in res_list), _e(__version__), _e(res_list[0].version),
                 datetime.datetime.utcnow().strftime("%Y-%m-%d %H:%M"))]
    sessions = A.collect_sessions(res_list)
    if len(sessions) > 1:
        parts.append(group_html(sessions, default))
    problems = []
    for res in res_list:
        for inp in B.resolve_inputs(res, signals, log, validation):
            s = inp.session
            parts.append("<h2>Session %s</h2>" % _e(s.participant))
            info = s.session or {}
            c = s.counts or {}
            parts.append(html_table(["log", "participant", "session", "source", "software", "sample rate [Hz]",
                                     "trials", "perturbed", "used", "cut-off used [Hz]"],
                                    [[_e(s.log), _e(info.get("participant_id", "")), _e(info.get("session_id", "")),
                                      _e(info.get("source", "")), _e(info.get("software_version", "")),
                                      _e(info.get("sample_rate_hz", "")), _e(c.get("trials", "")),
                                      _e(c.get("perturbed", "")), _e(c.get("used", "")),
                                      _e(T.fmt_num(s.cutoff_used_hz))]], left_cols=(0, 1, 2, 3, 4), cls="info",
                                    col_classes={0: "wrap"}))
            parts.append("<h3>Summary (Table 1 layout): estimate [95 % interval]</h3>")
            parts.append(session_table_html(s, default))
            err = T.truth_error_text(s)
            if err:
                parts.append("<h3>Error vs truth: (estimate - truth) / truth</h3><pre>%s</pre>"
                             % _e(err.split("\n", 1)[1]))
            parts.append(directional_html(s, default))
            figs = B.session_figures(inp, None, all_trials, default)
            parts.append("<h3>Figures</h3>")
            for name, fig in figs.items():
                parts.append("<figure>%s<figcaption>%s</figcaption></figure>" % (
                    fig_to_img(fig, name, caption_of(name) or name), _e(caption_of(name))))
            parts.append("<h3>Excluded trials</h3>")
            if s.issues:
                parts.append(html_table(["trial", "reason"], [[_e(i.get("trial", "")), _e(i.get("reason", ""))]
                                                             for i in s.issues], left_cols=(1,), cls="issues"))
            else:
                parts.append("<p>none</p>")
            parts.append("<h3>Warnings</h3>")
            warn = list(s.warnings) + inp.notes
            parts.append("<ul class='warn'>%s</ul>" % "".join("<li>%s</li>" % _e(w) for w in warn) if warn else "<p>none</p>")
            problems += [n for n in inp.notes if "not drawn" in n]
            st = dict(res.settings)
            st.update(s.settings or {})
            parts.append("<h3>Settings used</h3>")
            parts.append(html_table(["setting", "value"], [[_e(k), _e(json.dumps(v))] for k, v in sorted(st.items())],
                                    left_cols=(0, 1), cls="settings", col_classes={1: "wrap"}))
    # Lets a headless browser test confirm every figure decoded (naturalWidth > 0).
    parts.append("<script>window.addEventListener('load',function(){var n=0;for(var i=0;i<document.images.length;i++)"
                 "{if(document.images[i].naturalWidth>0)n++;}document.body.setAttribute('data-images-decoded',n);});"
                 "</script>")
    parts.append("</body></html>")
    return "\n".join(parts), problems


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m manipplot.report", description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="+", help="estimate_impedance --json output(s)")
    ap.add_argument("--signals", help="estimate_impedance --export-signals directory")
    ap.add_argument("--log", help="the session's LCM log (or a directory of logs)")
    ap.add_argument("--validation", help="manip_sim --validate DIR/validation.json")
    ap.add_argument("--all-trials", action="store_true", help="Fig. 5 for every exported trial")
    ap.add_argument("-o", "--out", required=True, help="output HTML file")
    a = ap.parse_args(argv)
    try:
        res = [load_results(p) for p in a.results]
    except (OSError, ValueError) as e:
        print("manipplot.report: %s" % e, file=sys.stderr)
        return 2
    page, problems = build_report(res, a.signals, a.log, a.validation, a.all_trials)
    d = os.path.dirname(os.path.abspath(a.out))
    os.makedirs(d, exist_ok=True)
    tmp = a.out + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(page)
    os.replace(tmp, a.out)
    for p in problems:
        print("manipplot.report: %s" % p, file=sys.stderr)
    print(a.out)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
