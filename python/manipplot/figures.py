"""Paper-quality matplotlib figures (one column, 3.5 in wide).

Every function returns a :class:`matplotlib.figure.Figure` (no pyplot state,
safe in servers and tests); :func:`save` writes it as PNG and PDF/SVG.
Ticks come from matplotlib's locators (round values), every axis label has its
unit, x1/x2 have distinct colours *and* line styles, legends show line samples.
"""
from __future__ import annotations

import math
import os
from typing import Dict, List, Optional, Sequence

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.ticker import FuncFormatter, MaxNLocator, MultipleLocator, ScalarFormatter  # noqa: E402

from . import analysis as A  # noqa: E402
from .io import BIASED_METHODS, ELEMENTS, SessionResult, Summary  # noqa: E402

COLUMN_IN = 3.5
AXIS_STYLE = {0: dict(color="#0072B2", ls="-"), 1: dict(color="#D55E00", ls="--")}   # x1, x2 (colour-blind safe)
TRUTH_STYLE = dict(color="0.15", lw=0.8, ls=":")
RC = {
    "font.size": 7.5, "axes.labelsize": 7.5, "axes.titlesize": 7.5, "legend.fontsize": 6.5,
    "xtick.labelsize": 7, "ytick.labelsize": 7, "lines.linewidth": 1.1, "axes.linewidth": 0.6,
    "axes.unicode_minus": False, "savefig.dpi": 200, "legend.frameon": False, "font.family": "DejaVu Sans",
    "svg.fonttype": "none", "pdf.fonttype": 42, "axes.spines.top": False, "axes.spines.right": False,
}
SIGNAL_LABEL = {"dx": "Δx", "dxd": "Δẋ", "dxdd": "Δẍ", "du_ext": "Δu_ext"}


class PlainFormatter(ScalarFormatter):
    """ScalarFormatter with an ASCII minus whatever the global rcParams say, no offset text."""

    def __init__(self):
        super().__init__(useOffset=False, useMathText=False)

    def fix_minus(self, s):
        return s.replace("\u2212", "-")


def _fig(h_in: float, nrows=1, ncols=1, **kw) -> (Figure, np.ndarray):
    with matplotlib.rc_context(RC):
        fig = Figure(figsize=(COLUMN_IN, h_in), layout="constrained")
        axs = fig.subplots(nrows, ncols, squeeze=False, **kw)
    fig._manip_rc = RC
    return fig, axs


def _style(ax):
    with matplotlib.rc_context(RC):
        ax.tick_params(labelsize=RC["xtick.labelsize"], width=0.6, length=2.5)
        for sp in ("top", "right"):
            ax.spines[sp].set_visible(False)
        ax.yaxis.set_major_locator(MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10]))
        ax.yaxis.set_major_formatter(PlainFormatter())
        ax.xaxis.set_major_formatter(PlainFormatter())
        ax.yaxis.label.set_size(RC["axes.labelsize"])
        ax.xaxis.label.set_size(RC["axes.labelsize"])


def save(fig: Figure, path_stem: str, formats: Sequence[str] = ("png", "pdf"), dpi: Optional[float] = None) -> List[str]:
    """Write ``<path_stem>.<fmt>`` for each format (PNG at ``dpi``, default 200); returns the paths."""
    d = os.path.dirname(path_stem)
    if d:
        os.makedirs(d, exist_ok=True)
    out = []
    with matplotlib.rc_context(RC):
        for f in formats:
            p = "%s.%s" % (path_stem, f)
            fig.savefig(p, format=f, dpi=dpi or RC["savefig.dpi"], bbox_inches="tight", pad_inches=0.02,
                        metadata={"Creator": "manipplot"} if f in ("png", "svg", "pdf") else None)
            out.append(p)
    return out


def add_output_options(ap, dpi_help: str = "PNG resolution (default 200)") -> None:
    """The output options every figure command shares: --format, --dpi, -o/--out."""
    ap.add_argument("--format", default="png,pdf", help="comma-separated: png, pdf, svg (default png,pdf)")
    ap.add_argument("--dpi", type=float, default=200, help=dpi_help)
    ap.add_argument("-o", "--out", required=True, help="output directory")


def output_formats(ap, a) -> List[str]:
    """The --format list, or the parser's usage error (exit 2) naming what is unknown."""
    fmts = [f.strip() for f in a.format.split(",") if f.strip()]
    bad = [f for f in fmts if f not in ("png", "pdf", "svg")]
    if bad:
        ap.error("unknown format(s): %s" % ", ".join(bad))
    return fmts


def _text(fig, **kw):
    with matplotlib.rc_context(RC):
        return fig


# --------------------------------------------------------------------------- Fig. 3
def fig_psd(p: A.Psds, cutoff_used_hz: Optional[float] = None, fmax_hz: float = 30.0) -> Figure:
    """Fig. 3: mean PSD of the principal-axis jerk, unperturbed vs perturbed, in dB
    re the peak of the unperturbed PSD; the unperturbed + threshold curve (the
    auto cut-off rule), the auto cut-off and the cut-off used are marked."""
    fig, axs = _fig(3.0)
    ax = axs[0, 0]
    _style(ax)
    sel = (p.f_hz > 0) & (p.f_hz <= fmax_hz)
    f = p.f_hz[sel]
    with matplotlib.rc_context(RC):
        if p.n_unperturbed:
            ax.plot(f, p.db(p.p_unperturbed[sel]), color="#0072B2", label="unperturbed (n = %d)" % p.n_unperturbed)
            ax.plot(f, p.db(p.p_unperturbed[sel]) + p.threshold_db, color="#0072B2", lw=0.7, ls=":",
                    label="unperturbed + %g dB (threshold)" % p.threshold_db)
        if p.n_perturbed:
            ax.plot(f, p.db(p.p_perturbed[sel]), color="#D55E00", ls="--", label="perturbed (n = %d)" % p.n_perturbed)
        if p.cutoff_auto_hz is not None:
            i = int(np.argmin(np.abs(p.f_hz - p.cutoff_auto_hz)))
            ax.plot([p.cutoff_auto_hz], [p.db(p.p_perturbed[i])], "o", ms=3.5, mfc="none", color="k",
                    label="auto cut-off %.3g Hz" % p.cutoff_auto_hz)
        if cutoff_used_hz:
            ax.axvline(cutoff_used_hz, color="0.3", lw=0.8, ls="-.", label="cut-off used f_c,HP = %.3g Hz" % cutoff_used_hz)
        ax.set_xscale("log")
        ax.set_xlim(max(f[0], 0.1), fmax_hz)
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: "%g" % v))
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel("jerk x2 PSD [dB re unpert. peak]")
        lo = np.nanmin(p.db(p.p_unperturbed[sel])) if p.n_unperturbed else -60
        ax.set_ylim(max(lo - 5, -80), None)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, handlelength=2.2, columnspacing=1.0)
        ax.set_title("0 dB = %.3g (m/s³)²/Hz (unperturbed peak at %.3g Hz)" % (p.reference, p.peak_unperturbed_hz),
                     fontsize=6.5, loc="left")
    return fig


# --------------------------------------------------------------------------- Fig. 4
def fig_nrmse(c: A.Nrmse, bounds: Dict[str, float] = A.PAPER_BOUNDS) -> Figure:
    """Fig. 4: NRMSE(dt) per signal (panel) and axis (x1 solid blue, x2 dashed
    orange; bands = +-1 std over trials), the paper's bound as a grey line."""
    fig, axs = _fig(3.2, 2, 2, sharex=True)
    t_ms = c.dt_s * 1e3
    with matplotlib.rc_context(RC):
        for ax, s in zip(axs.ravel(), A.SIGNALS):
            _style(ax)
            for a in (0, 1):
                m, sd = 100 * c.mean[s][:, a], 100 * c.std[s][:, a]
                ax.plot(t_ms, m, label="x%d" % (a + 1), **AXIS_STYLE[a])
                ax.fill_between(t_ms, np.maximum(m - sd, 0), m + sd, color=AXIS_STYLE[a]["color"], alpha=0.15, lw=0)
            b = 100 * bounds[s]
            ax.axhline(b, color="0.45", lw=0.8, ls="-.", label="paper bound")
            ax.text(0.5 * t_ms[-1], b, "%g %%" % b, va="bottom", ha="center", fontsize=6, color="0.3")
            top = max(1.6 * b, float(np.max(100 * (c.mean[s] + c.std[s])))) * 1.1
            ax.set_ylim(0, top)
            ax.set_xlim(0, t_ms[-1])
            ax.xaxis.set_major_locator(MultipleLocator(50))
            ax.set_title(SIGNAL_LABEL[s], loc="left", fontsize=7.5)
            ax.set_ylabel("NRMSE [%]")
        for ax in axs[1]:
            ax.set_xlabel("Δt [ms]")
        axs[0, 0].legend(loc="upper left", handlelength=2.2)
        fig.suptitle("NRMSE vs twin truth, %s isolation (n = %d trials)" % (c.isolation, c.n_trials), fontsize=7)
    return fig


# --------------------------------------------------------------------------- Fig. 5
def fig_variational(sig: Dict[str, np.ndarray], truth: Optional[Dict[str, np.ndarray]] = None,
                    trial: Optional[int] = None, angle_deg: Optional[float] = None) -> Figure:
    """Fig. 5: u_pert, Δu_ext, Δẍ, Δẋ, Δx of one perturbed trial in separate panels
    with units; the twin truth dotted where the log has it."""
    panels = [("u_pert", "u_pert [N]", 1.0), ("du_ext", "Δu_ext [N]", 1.0), ("dxdd", "Δẍ [m/s²]", 1.0),
              ("dxd", "Δẋ [mm/s]", 1e3), ("dx", "Δx [mm]", 1e3)]
    fig, axs = _fig(4.6, len(panels), 1, sharex=True)
    t_ms = sig["t_s"] * 1e3
    truth = dict(truth or {})
    if "dx" not in truth and "dx_true" in sig:
        truth["dx"] = sig["dx_true"]
    with matplotlib.rc_context(RC):
        for ax, (key, label, scale) in zip(axs[:, 0], panels):
            _style(ax)
            ax.yaxis.set_major_locator(MaxNLocator(nbins=3, steps=[1, 2, 2.5, 5, 10]))
            for a in (0, 1):
                ax.plot(t_ms, scale * sig[key][:, a], label="x%d" % (a + 1), **AXIS_STYLE[a])
            if key in truth and key != "u_pert":
                n = min(len(t_ms), len(truth[key]))
                for a in (0, 1):
                    ax.plot(t_ms[:n], scale * truth[key][:n, a], label="truth" if a == 0 else None, **TRUTH_STYLE)
            ax.axhline(0, color="0.7", lw=0.5, zorder=0)
            ax.set_ylabel(label)
            ax.yaxis.set_label_coords(-0.16, 0.5)
        axs[-1, 0].set_xlabel("time after onset [ms]")
        axs[-1, 0].set_xlim(0, t_ms[-1])
        axs[-1, 0].xaxis.set_major_locator(MultipleLocator(25))
        handles, labels = axs[-1, 0].get_legend_handles_labels()
        axs[0, 0].legend(handles, labels, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=3, handlelength=2.2)
        title = "Variational dynamics"
        if trial is not None:
            title += ", trial %d" % trial
        if angle_deg is not None and math.isfinite(angle_deg):
            title += ", φ = %g°" % round(angle_deg, 1)
        fig.suptitle(title, fontsize=7)
    return fig


# --------------------------------------------------------------------------- directional D, K per angle
def fig_directional(s: SessionResult, method: str) -> Figure:
    """u^T D u and u^T K u per perturbation angle (points with 95 % intervals; flagged
    fits hollow), the session's full 2x2 estimate as u^T M u over all angles (solid),
    and the truth (dotted) for simulated logs."""
    rows = A.directional_table(s, method)
    sess = s.summary(method, "session")
    Dt, Kt = s.truth_mats()
    fig, axs = _fig(3.3, 2, 1, sharex=True)
    grid = np.linspace(0, 360, 361)
    with matplotlib.rc_context(RC):
        for ax, which, unit in ((axs[0, 0], "D", "N s/m"), (axs[1, 0], "K", "N/m")):
            _style(ax)
            pts = [r for r in rows if r.which == which]
            if sess is not None and getattr(sess, which) is not None:
                ax.plot(grid, A.quad(getattr(sess, which), grid), color="#009E73", lw=1.0,
                        label="session estimate (%s)" % method)
            truth = Dt if which == "D" else Kt
            if truth is not None:
                ax.plot(grid, A.quad(truth, grid), **dict(TRUTH_STYLE, lw=1.0), label="truth (simulated)")
            # y range from the session estimate and the truth (when present): per-angle values far
            # outside are drawn as triangles at the edge ("off scale"), their numbers are in the table.
            refs = [A.quad(M, grid) for M in (getattr(sess, which) if sess is not None else None, truth)
                    if M is not None]
            ylim = None
            if refs:
                r_lo, r_hi = min(0.0, float(np.min(refs))), float(np.max(refs))
                span = max(r_hi - r_lo, 1e-9)
                ylim = (r_lo - 0.6 * span, r_hi + 0.8 * span)
            for flagged in (False, True):
                sel = [r for r in pts if (r.identifiable is False) == flagged]
                if not sel:
                    continue
                x = np.array([r.angle_deg for r in sel])
                y = np.array([r.value for r in sel])
                lo = np.array([r.lo if r.lo is not None else r.value for r in sel])
                hi = np.array([r.hi if r.hi is not None else r.value for r in sel])
                inside = np.ones(len(y), bool) if ylim is None else (y >= ylim[0]) & (y <= ylim[1])
                if inside.any():
                    ax.errorbar(x[inside], y[inside], yerr=[(y - lo)[inside], (hi - y)[inside]], fmt="o", ms=3.2,
                                capsize=2, lw=0.8, color="k", mfc="none" if flagged else "k",
                                label="per angle, flagged fit" if flagged else "per angle (95 % interval)")
                for up in (True, False):
                    off = ~inside & ((y > ylim[1]) if up else (y < ylim[0])) if ylim is not None else np.zeros(len(y), bool)
                    if off.any():
                        ax.plot(x[off], np.full(off.sum(), ylim[1] if up else ylim[0]), "^" if up else "v", ms=4,
                                color="#CC79A7", clip_on=False, label="per angle, off scale (see table)")
            if ylim is not None:
                ax.set_ylim(*ylim)
            ax.set_ylabel("u%s%su [%s]" % ("ᵀ", which, unit))
        ax = axs[1, 0]
        ax.set_xlim(0, 360)
        ax.xaxis.set_major_locator(MultipleLocator(90))
        ax.set_xlabel("perturbation angle φ [deg]")
        h, l = [], []
        for ax in axs[:, 0]:
            for hh, ll in zip(*ax.get_legend_handles_labels()):
                if ll not in l:
                    h.append(hh)
                    l.append(ll)
        axs[0, 0].legend(h, l, loc="lower center", bbox_to_anchor=(0.5, 1.02), ncol=2, fontsize=6, handlelength=2.2)
        kind = next((r.interval for r in rows), "")
        fig.suptitle("Impedance along the push u = (cos φ, sin φ), %s%s%s"
                     % (method, " (BIASED method)" if method in BIASED_METHODS else "",
                        "\nintervals: %s" % kind if kind else ""), fontsize=6.5)
    return fig


# --------------------------------------------------------------------------- Table 1
def fig_table1(title: str, cells: Dict[str, str], note: str = "") -> Figure:
    """A Table-1 style figure: D [N s/m] and K [N/m] as 2x2 blocks side by side; ``cells`` maps
    'D11'..'K22' to the text of that cell (e.g. '10.98 (4.85)'). Every text has a gid
    ('header:D', 'cell:D11', ...) so tests can find it."""
    # One column wide unless the cells need more: the figure widens, cells never overlap.
    longest = max([len(line) for v in cells.values() for line in str(v).splitlines()] + [1])
    width = max(COLUMN_IN, 4 * longest * 6.0 * 0.62 / 72.0 + 0.3)
    two_lines = any("\n" in str(v) for v in cells.values())
    fig, axs = _fig(1.4 if two_lines else 1.1)
    fig.set_size_inches(width, fig.get_size_inches()[1])
    ax = axs[0, 0]
    ax.set_axis_off()
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    with matplotlib.rc_context(RC):
        xs = {"1": (0.125, 0.625), "2": (0.375, 0.875)}   # column within block -> x of D, x of K
        for which, x in (("D", 0.25), ("K", 0.75)):
            t = ax.text(x, 0.86, "%s [%s]" % ("Damping D" if which == "D" else "Stiffness K",
                                              "N s/m" if which == "D" else "N/m"),
                        ha="center", va="center", fontsize=6.5, weight="bold")
            t.set_gid("header:%s" % which)
        ax.plot([0.02, 0.98], [0.72, 0.72], color="k", lw=0.6)
        ax.plot([0.02, 0.98], [0.08, 0.08], color="k", lw=0.6)
        ax.plot([0.5, 0.5], [0.1, 0.95], color="0.6", lw=0.5)
        for r, y in (("1", 0.55), ("2", 0.27)):
            for c in ("1", "2"):
                for i, which in enumerate(("D", "K")):
                    name = "%s%s%s" % (which, r, c)
                    t = ax.text(xs[c][i], y, cells.get(name, ""), ha="center", va="center", fontsize=6)
                    t.set_gid("cell:%s" % name)
        ax.set_title(title, fontsize=6.5)
        if note:
            fig.text(0.01, 0.0, note, fontsize=5.5, color="#b00000", ha="left", va="bottom")
    return fig
