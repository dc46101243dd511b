"""Checks of figure content through matplotlib's objects (not pixels)."""
import re

from matplotlib.backends.backend_agg import FigureCanvasAgg

UNIT_RE = re.compile(r"\[[^\]]+\]")


def draw(fig):
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


def tick_texts(ax, axis="y"):
    a = ax.yaxis if axis == "y" else ax.xaxis
    lo, hi = sorted(ax.get_ylim() if axis == "y" else ax.get_xlim())
    out = []
    for t in a.get_majorticklabels():
        if t.get_visible() and t.get_text() and lo - 1e-9 * (hi - lo + 1) <= (t.get_position()[1 if axis == "y" else 0]) <= hi + 1e-9 * (hi - lo + 1):
            out.append(t)
    return out


def parse(text):
    return float(text.replace("\u2212", "-"))


def significant_digits(text):
    s = text.replace("\u2212", "-").lstrip("-").replace(".", "").lstrip("0").rstrip("0")
    return len(s)


def check_axes(tc, fig, data_axes, max_digits=3):
    """Every data axes: x and y labels with units, round tick labels that parse back to their
    positions (sign included), labels inside the figure, y label not overlapping tick labels,
    legends with line samples."""
    r = draw(fig)
    fb = fig.bbox
    for ax in data_axes:
        tc.assertRegex(ax.get_ylabel(), UNIT_RE, "y label without unit")
        for axis in ("x", "y"):
            ticks = tick_texts(ax, axis)
            if axis == "x" and not any(t.get_text() for t in ticks):
                continue   # shared x, labels only on the bottom panel
            tc.assertGreaterEqual(len(ticks), 2, "fewer than 2 %s tick labels" % axis)
            for t in ticks:
                txt = t.get_text()
                v = parse(txt)
                pos = t.get_position()[1 if axis == "y" else 0]
                if ax.get_xscale() == "linear" or axis == "y":
                    tc.assertAlmostEqual(v, pos, delta=1e-9 * max(1.0, abs(pos)), msg="tick text %r at %g" % (txt, pos))
                tc.assertLessEqual(significant_digits(txt), max_digits, "unrounded tick %r" % txt)
                bb = t.get_window_extent(r)
                tc.assertTrue(bb.x0 >= fb.x0 - 1 and bb.x1 <= fb.x1 + 1 and bb.y0 >= fb.y0 - 1 and bb.y1 <= fb.y1 + 1,
                              "tick label %r outside the figure (clipped)" % txt)
        yl = ax.yaxis.label.get_window_extent(r)
        for t in tick_texts(ax, "y"):
            tc.assertFalse(yl.overlaps(t.get_window_extent(r)), "y label overlaps tick label %r" % t.get_text())
        if ax.get_xlabel():
            tc.assertRegex(ax.get_xlabel(), UNIT_RE, "x label without unit")


def legend_entries(fig):
    out = []
    for ax in fig.axes:
        leg = ax.get_legend()
        if leg is None:
            continue
        handles = getattr(leg, "legend_handles", None) or getattr(leg, "legendHandles")
        for h, t in zip(handles, leg.get_texts()):
            out.append((t.get_text(), h))
    return out
