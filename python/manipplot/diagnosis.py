"""Figures of a ``diagnose_model --json`` report (docs/diagnosis.md, "Figures (--plots)").

    python3 -m manipplot.diagnosis REPORT.json -o DIR [--format png,pdf,svg] [--dpi 200]

``diagnose_model ... --plots DIR`` calls this on its report. Files (each
.png/.pdf/...), every number read from the report JSON:

diag_prediction     measured vs held-out predicted response (single joint: one
                    fold's first seconds; manipulandum: three example trials)
diag_residual_time  manipulandum: mean held-out residual per time after onset,
                    95 % band, before vs after the extension
diag_gains          first-round held-out gain per candidate (fold gains, mean +- SE,
                    significant and accepted marked)
diag_xcorr          residual cross-correlation with the candidate regressors and
                    its 95 % bound, before vs after
diag_fold_vaf       held-out VAF per fold (time order), before vs after
diag_impedance      manipulandum: D and K per element before -> after
                    (equation error; the estimator's default method, refitted)
diagnosis.json      the report the figures were drawn from

Artists carry a gid naming the JSON numbers they show (tests and lab scripts
find them by it). Exit codes: 0 ok, 2 bad command line or unreadable report,
1 some figures could not be drawn (named on stderr).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
from typing import Dict, List, Optional

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from .figures import COLUMN_IN, RC, _fig, _style, add_output_options, output_formats, save  # noqa: E402

# before (baseline) / after (extended model): colour *and* line style / marker differ.
BEFORE = dict(color="#0072B2", ls="--", marker="o")
AFTER = dict(color="#D55E00", ls="-", marker="s")
MEASURED = dict(color="0.15", ls="-", lw=0.9)
ACCEPTED_COLOR = "#009E73"

ELEMENTS_D = ("D11", "D12", "D21", "D22")
ELEMENTS_K = ("K11", "K12", "K22")
# index of an element in the row-major 2x2 arrays of the JSON (K12 = K21)
ELEMENT_INDEX = {"D11": 0, "D12": 1, "D21": 2, "D22": 3, "K11": 0, "K12": 1, "K22": 3}


def _unit_word(rep) -> str:
    return (rep.get("traces") or {}).get("unit") or ("N" if "manipulandum" in rep else "N m")


def _line(ax, x, y, style, **kw):
    st = dict(style)
    st.pop("marker", None)
    return ax.plot(x, y, **st, **kw)[0]


def _legend_below(ax, fig, ncol=3):
    h, l = [], []
    for a in fig.axes:
        for hh, ll in zip(*a.get_legend_handles_labels()):
            if ll not in l:
                h.append(hh)
                l.append(ll)
    ax.legend(h, l, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=ncol, handlelength=2.4, fontsize=6)


# --------------------------------------------------------------------------- 1. measured vs predicted
def fig_prediction(rep: dict) -> Figure:
    """Single joint: measured torque, held-out baseline and extended predictions over
    one fold's first seconds (top) and the residuals (bottom). Manipulandum: the target
    Δu_ext − M_BSP Δẍ of three trials per axis vs the held-out predictions."""
    tr = rep["traces"]
    unit = tr.get("unit", "N m")
    if tr["kind"] == "single_joint":
        t = np.asarray(tr["t_s"])
        y, b0 = np.asarray(tr["measured"]), np.asarray(tr["baseline"])
        b1 = None if tr.get("extended") is None else np.asarray(tr["extended"])
        fig, axs = _fig(3.4, 2, 1, sharex=True, gridspec_kw=dict(height_ratios=[2, 1]))
        ax, axr = axs[0, 0], axs[1, 0]
        with matplotlib.rc_context(RC):
            for a in (ax, axr):
                _style(a)
            ax.plot(t, y, label="measured", gid="measured", **MEASURED)
            _line(ax, t, b0, BEFORE, lw=0.9, label="baseline (VAF %.3f)" % tr["vaf_baseline"], gid="baseline")
            _line(axr, t, y - b0, BEFORE, lw=0.8, gid="residual_baseline")
            if b1 is not None:
                _line(ax, t, b1, AFTER, lw=0.9, label="extended (VAF %.3f)" % tr["vaf_extended"], gid="extended")
                _line(axr, t, y - b1, AFTER, lw=0.8, gid="residual_extended")
            axr.axhline(0, color="0.7", lw=0.5, zorder=0)
            ax.set_ylabel("%s [%s]" % ("torque", unit))
            axr.set_ylabel("residual [%s]" % unit)
            axr.set_xlabel("time in record [s]")
            axr.set_xlim(t[0], t[-1])
            axr.xaxis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 2.5, 5, 10]))
            _legend_below(ax, fig)
            fig.suptitle("Held-out prediction, fold %d of %d (time order)%s"
                         % (tr["fold"] + 1, rep.get("folds", 0),
                            "\nextended: " + " + ".join(tr.get("extended_model") or []) if b1 is not None else ""),
                         fontsize=6.5)
        return fig
    t_ms = 1e3 * np.asarray(tr["t_after_onset_s"])
    trials = tr["trials"]
    with matplotlib.rc_context(RC):   # no layout engine: a figure legend above the panels (see below)
        fig = Figure(figsize=(COLUMN_IN, 1.0 + 1.1 * len(trials)))
        axs = fig.subplots(len(trials), 2, squeeze=False, sharex=True)
    fig._manip_rc = RC
    with matplotlib.rc_context(RC):
        for i, trl in enumerate(trials):
            for a in (0, 1):
                ax = axs[i, a]
                _style(ax)
                ax.yaxis.set_major_locator(MaxNLocator(nbins=4, steps=[1, 2, 2.5, 5, 10]))
                ax.plot(t_ms, trl["target"][a], label="target Δu_ext − M_BSP Δẍ", gid="target:%d:%d" % (i, a), **MEASURED)
                _line(ax, t_ms, trl["baseline"][a], BEFORE, lw=0.9, label="baseline D Δẋ + K Δx", gid="baseline:%d:%d" % (i, a))
                if trl.get("extended") is not None:
                    _line(ax, t_ms, trl["extended"][a], AFTER, lw=0.9, label="extended", gid="extended:%d:%d" % (i, a))
                ax.axhline(0, color="0.7", lw=0.5, zorder=0)
                ax.set_title("trial %d, x%d" % (trl["trial"], a + 1), loc="left", fontsize=6.5, pad=2)
                ax.set_ylabel("force [%s]" % unit)
        for a in (0, 1):
            axs[-1, a].set_xlabel("time after onset [ms]")
            axs[-1, a].set_xlim(0, t_ms[-1])
            axs[-1, a].xaxis.set_major_locator(MaxNLocator(nbins=3, steps=[1, 2.5, 5, 10]))
        # a figure legend above the panels (constrained layout of matplotlib 3.6 ignores figure legends)
        top = 1.0 - 0.75 / fig.get_figheight()
        fig.subplots_adjust(left=0.16, right=0.98, bottom=0.45 / fig.get_figheight(), top=top, wspace=0.5, hspace=0.55)
        h, l = axs[0, 0].get_legend_handles_labels()
        fig.legend(h, l, loc="lower center", bbox_to_anchor=(0.5, top + 0.15 / fig.get_figheight()), ncol=2,
                   fontsize=6, handlelength=2.4)
        fig.suptitle("Held-out prediction of three trials (%s)"
                     % ("extended: " + " + ".join(tr["extended_model"]) if tr.get("extended_model") else "no extension"),
                     fontsize=6.5, y=0.995)
    return fig


def fig_residual_time(rep: dict) -> Figure:
    """Manipulandum: mean held-out residual over trials per time after onset, per axis,
    with its 95 % band (1.96 SD / sqrt(n)), baseline vs extended model."""
    tr = rep["traces"]
    unit = tr.get("unit", "N")
    t_ms = 1e3 * np.asarray(tr["t_after_onset_s"])
    fig, axs = _fig(3.0, 2, 1, sharex=True)
    with matplotlib.rc_context(RC):
        for a in (0, 1):
            ax = axs[a, 0]
            _style(ax)
            for key, st, name in (("before", BEFORE, "baseline"), ("after", AFTER, "extended")):
                m = tr.get("mean_residual_" + key)
                if m is None:
                    continue
                m = np.asarray(m[a])
                h = np.asarray(tr["ci95_halfwidth_" + key][a])
                _line(ax, t_ms, m, st, label="%s (mean, 95 %% band)" % name, gid="mean_%s:%d" % (key, a))
                ax.fill_between(t_ms, m - h, m + h, color=st["color"], alpha=0.18, lw=0, gid="band_%s:%d" % (key, a))
            ax.axhline(0, color="0.6", lw=0.5, zorder=0)
            ax.set_ylabel("x%d mean residual [%s]" % (a + 1, unit))
        axs[1, 0].set_xlabel("time after onset [ms]")
        axs[1, 0].set_xlim(0, t_ms[-1])
        _legend_below(axs[0, 0], fig, ncol=2)
        fig.suptitle("Where in the window the model misfits (held-out, n = %d trials)" % tr["n_trials"], fontsize=6.5)
    return fig


# --------------------------------------------------------------------------- 2. gain per candidate
def first_round(rep: dict) -> Optional[dict]:
    rounds = rep.get("rounds") or []
    return rounds[0] if rounds else None


def fig_gains(rep: dict) -> Figure:
    """First round of the search: per candidate its held-out gain per fold (points),
    mean +- SE (bar), significant (Holm) marked '*', the accepted one in green."""
    r = first_round(rep)
    cands = r["candidates"]
    fig, axs = _fig(0.9 + 0.32 * len(cands), 1, 1)
    ax = axs[0, 0]
    _style(ax)
    rng = np.random.default_rng(0)
    names = []
    with matplotlib.rc_context(RC):
        for i, c in enumerate(cands):
            y = len(cands) - 1 - i
            names.append(c["id"])
            if "not_applicable" in c:
                ax.text(0.0, y, "  not applicable", va="center", fontsize=6, color="0.4", gid="na:" + c["id"])
                continue
            accepted = r.get("accepted") == c["id"]
            col = ACCEPTED_COLOR if accepted else ("k" if c["significant"] else "0.45")
            g = 100 * np.asarray(c["fold_gain"], float)
            ax.plot(g, y + 0.12 * rng.uniform(-1, 1, len(g)), ls="none", marker=".", ms=3, color="0.6",
                    gid="folds:" + c["id"], label="fold gain")
            ax.errorbar([100 * c["mean_gain"]], [y], xerr=[100 * c["se"]], fmt="D" if accepted else "o", ms=3.8,
                        color=col, mfc=col if (accepted or c["significant"]) else "none", capsize=2, lw=0.9,
                        gid="mean:" + c["id"],
                        label="accepted" if accepted else ("significant (Holm)" if c["significant"] else "mean ± SE"))
            tag = ("* " if c["significant"] else "") + "p_Holm=%.2g" % c["p_holm"] + (" ACCEPTED" if accepted else "") \
                + (" implausible" if c.get("implausible") else "")
            ax.annotate(tag, (1.0, y), xycoords=("axes fraction", "data"), xytext=(2, 0), textcoords="offset points",
                        va="center", fontsize=5.5, color=col, gid="tag:" + c["id"], annotation_clip=False)
        ax.axvline(0, color="0.6", lw=0.6, zorder=0)
        ax.set_yticks(range(len(cands)))
        ax.set_yticklabels(names[::-1], fontsize=6)
        ax.set_ylim(-0.6, len(cands) - 0.4)
        ax.xaxis.set_major_locator(MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10]))
        ax.set_xlabel("held-out gain 1 − SSE_ext/SSE_base [%]")
        h, l = [], []
        for hh, ll in zip(*ax.get_legend_handles_labels()):
            if ll not in l:
                h.append(hh)
                l.append(ll)
        ax.legend(h, l, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=4, fontsize=6, handlelength=1.5)
        fig.suptitle("Round 1: held-out gain per candidate (%d folds)" % rep.get("folds", 0), fontsize=6.5)
    return fig


# --------------------------------------------------------------------------- 3. residual cross-correlation
def fig_xcorr(rep: dict) -> Figure:
    """|ρ| of the residual with each candidate regressor (largest over the lags
    searched; signed), before and after the extension, with the 95 % bound."""
    before = rep["signatures_before"]["xcorr"]
    after = rep["signatures_after"]["xcorr"] if rep.get("misfit") else None
    regs = [c["regressor"] for c in before]
    fig, axs = _fig(0.9 + 0.3 * len(regs), 1, 1)
    ax = axs[0, 0]
    _style(ax)
    n = len(regs)
    with matplotlib.rc_context(RC):
        sets = [("before", before, BEFORE, "baseline residual")]
        if after is not None:
            sets.append(("after", after, AFTER, "extended-model residual"))
        w = 0.36 if after is not None else 0.6
        for j, (key, xc, st, name) in enumerate(sets):
            off = (0.5 - j) * w if after is not None else 0.0
            ys = np.array([n - 1 - i + off for i in range(n)])
            rho = np.array([c["rho"] for c in xc])
            bnd = np.array([c["bound95"] for c in xc])
            ax.barh(ys, rho, height=w * 0.9, color=st["color"], alpha=0.85 if key == "before" else 1.0,
                    hatch=None if key == "before" else "////", edgecolor="white" if key == "before" else st["color"],
                    fill=key == "before", lw=0.6, label=name, gid="rho_" + key)
            ax.plot(np.concatenate([bnd, -bnd]), np.concatenate([ys, ys]), ls="none", marker="|", ms=5, mew=1.0,
                    color="k", label="95 % bound" if j == 0 else None, gid="bound_" + key)
            for y, c in zip(ys, xc):
                if c["significant"]:
                    ax.annotate("*", (c["rho"], y), xytext=(3 if c["rho"] >= 0 else -3, -2), textcoords="offset points",
                                ha="left" if c["rho"] >= 0 else "right", va="center", fontsize=7,
                                gid="significant_%s:%s" % (key, c["regressor"]))
        ax.axvline(0, color="0.5", lw=0.6)
        ax.set_yticks(range(n))
        ax.set_yticklabels(regs[::-1], fontsize=6)
        ax.set_ylim(-0.6, n - 0.4)
        lim = max(0.1, 1.25 * max(max(abs(c["rho"]), c["bound95"]) for c in before + (after or [])))
        ax.set_xlim(-lim, lim)
        ax.xaxis.set_major_locator(MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10], symmetric=True))
        ax.set_xlabel("cross-correlation ρ with the residual [-]")
        ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=3, fontsize=6, handlelength=1.8)
        fig.suptitle("Residual vs candidate regressors (* beyond the bound)", fontsize=6.5)
    return fig


# --------------------------------------------------------------------------- 4. VAF per fold
def fig_fold_vaf(rep: dict) -> Figure:
    """Held-out VAF per fold in time order (a trend exposes drift or changing
    impedance), baseline vs extended; the pooled held-out VAF as a thin line."""
    fig, axs = _fig(2.3, 1, 1)
    ax = axs[0, 0]
    _style(ax)
    with matplotlib.rc_context(RC):
        sets = [("before", rep["baseline"], BEFORE, "baseline")]
        if rep.get("misfit") and rep["final"].get("fold_vaf") is not None:
            sets.append(("after", rep["final"], AFTER, "extended"))
        for key, src, st, name in sets:
            v = 100 * np.asarray(src["fold_vaf"], float)
            k = np.arange(1, len(v) + 1)
            ax.plot(k, v, color=st["color"], ls=st["ls"], marker=st["marker"], ms=3.2, lw=0.9,
                    label="%s (pooled %.1f %%)" % (name, 100 * src["heldout_vaf"]["value"]), gid="fold_vaf_" + key)
            ax.axhline(100 * src["heldout_vaf"]["value"], color=st["color"], lw=0.5, ls=":", gid="pooled_vaf_" + key)
        ax.set_xlabel("fold (time order) [#]")
        ax.set_ylabel("held-out VAF [%]")
        ax.xaxis.set_major_locator(MaxNLocator(nbins=6, integer=True, steps=[1, 2, 5, 10]))
        ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=2, fontsize=6, handlelength=2.4)
    return fig


# --------------------------------------------------------------------------- 5. D, K before -> after
def impedance_rows(rep: dict) -> List[dict]:
    """Per estimate: label, D/K values and 95 % intervals per element (what diag_impedance plots)."""
    out = []
    for key, label in (("baseline", "equation error, baseline"), ("final", "equation error, extended")):
        if key == "final" and not rep.get("misfit"):
            continue
        ps = {p["name"]: p for p in rep[key]["params"]}
        row = {"label": label, "values": {}}
        for e in ELEMENTS_D + ELEMENTS_K:
            if e in ps:
                row["values"][e] = (ps[e]["value"], ps[e]["ci95"][0], ps[e]["ci95"][1])
        out.append(row)
    m = rep.get("manipulandum") or {}
    for key, label in (("default_method", "%s, no extension"), ("default_method_extended", "%s, with extension"),
                       ("default_method_refined", "%s, extension refined")):
        dm = m.get(key)
        if not dm or "D_Nspm" not in dm:
            continue
        meth = dm.get("method") or (m.get("default_method") or {}).get("method", "default")
        row = {"label": label % meth, "values": {}}
        for e in ELEMENTS_D + ELEMENTS_K:
            which = e[0]
            v = dm["%s_%s" % (which, "Nspm" if which == "D" else "Npm")][ELEMENT_INDEX[e]]
            lo = dm.get("%s_ci95_lo" % which, [v] * 4)[ELEMENT_INDEX[e]]
            hi = dm.get("%s_ci95_hi" % which, [v] * 4)[ELEMENT_INDEX[e]]
            row["values"][e] = (v, lo, hi)
        out.append(row)
    return out


IMP_STYLES = [dict(color="#0072B2", marker="o", mfc="none"), dict(color="#0072B2", marker="o"),
              dict(color="#D55E00", marker="s", mfc="none"), dict(color="#D55E00", marker="s"),
              dict(color="#CC79A7", marker="^")]


def fig_impedance(rep: dict) -> Figure:
    """D [N s/m] and K [N/m] per element, each estimate a dot with its 95 % interval:
    equation error before/after the extension and the estimator's default method
    without it, refitted with it, and with its amplitude refined."""
    rows = impedance_rows(rep)
    fig, axs = _fig(3.4, 2, 1)
    with matplotlib.rc_context(RC):
        for ax, elems, unit, which in ((axs[0, 0], ELEMENTS_D, "N s/m", "D"), (axs[1, 0], ELEMENTS_K, "N/m", "K")):
            _style(ax)
            nr = len(rows)
            for j, r in enumerate(rows):
                x = np.arange(len(elems)) + (j - (nr - 1) / 2) * 0.7 / max(nr, 1)
                v = np.array([r["values"][e][0] for e in elems])
                lo = np.array([r["values"][e][1] for e in elems])
                hi = np.array([r["values"][e][2] for e in elems])
                st = IMP_STYLES[j % len(IMP_STYLES)]
                ax.errorbar(x, v, yerr=[v - lo, hi - v], fmt=st["marker"], color=st["color"],
                            mfc=st.get("mfc", st["color"]), ms=3.2, capsize=1.5, lw=0.8, label=r["label"],
                            gid="%s:%s" % (which, r["label"]))
            ax.axhline(0, color="0.7", lw=0.5, zorder=0)
            ax.set_xticks(range(len(elems)))
            ax.set_xticklabels(elems)
            ax.set_xlim(-0.5, len(elems) - 0.5)
            ax.set_ylabel("%s [%s]" % ("damping" if which == "D" else "stiffness", unit))
        axs[0, 0].legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=2, fontsize=5.8, handlelength=1.5)
        fig.suptitle("Impedance before → after modelling the cause (95 % intervals)", fontsize=6.5)
    return fig


# --------------------------------------------------------------------------- driver
def figures(rep: dict, notes: Optional[List[str]] = None) -> Dict[str, Figure]:
    """All figures the report supports, by file stem; what cannot be drawn is named in notes."""
    notes = notes if notes is not None else []
    manip = "manipulandum" in rep
    out = {}
    todo = [("diag_prediction", fig_prediction, "traces")]
    if manip:
        todo.append(("diag_residual_time", fig_residual_time, "traces"))
    todo += [("diag_gains", fig_gains, "rounds"), ("diag_xcorr", fig_xcorr, "signatures_before"),
             ("diag_fold_vaf", fig_fold_vaf, "baseline")]
    if manip:
        todo.append(("diag_impedance", fig_impedance, "baseline"))
    for name, f, need in todo:
        if not rep.get(need):
            notes.append("%s not drawn: the report has no '%s' (diagnose_model --json of this version writes it)" % (name, need))
            continue
        out[name] = f(rep)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m manipplot.diagnosis", description=__doc__.split("\n\n")[0])
    ap.add_argument("report", help="diagnose_model --json output")
    add_output_options(ap)
    a = ap.parse_args(argv)
    fmts = output_formats(ap, a)
    try:
        with open(a.report, encoding="utf-8") as f:
            rep = json.load(f)
        if not isinstance(rep, dict) or "baseline" not in rep:
            raise ValueError("%s: not a diagnose_model report" % a.report)
    except (OSError, ValueError) as e:
        print("manipplot.diagnosis: %s" % e, file=sys.stderr)
        return 2
    os.makedirs(a.out, exist_ok=True)
    notes: List[str] = []
    for name, fig in figures(rep, notes).items():
        for p in save(fig, os.path.join(a.out, name), fmts, a.dpi):
            print(p)
    dst = os.path.join(a.out, "diagnosis.json")
    if os.path.abspath(dst) != os.path.abspath(a.report):
        shutil.copyfile(a.report, dst)
        print(dst)
    for n in notes:
        print("manipplot.diagnosis: %s" % n, file=sys.stderr)
    return 1 if notes else 0


if __name__ == "__main__":
    sys.exit(main())
