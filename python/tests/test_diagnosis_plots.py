"""diagnose_model --plots: the figures of manipplot.diagnosis checked against the report's numbers
through matplotlib's objects (Figures: synthetic reports, no apps), and the app end to end (App:
a small single-joint CSV made here, a short hidden-mechanism manipulandum log)."""
import contextlib
import hashlib
import io
import json
import os
import shutil
import subprocess
import tempfile
import unittest

import numpy as np

from manipplot import diagnosis as DG

from .figcheck import UNIT_RE, check_axes, draw, parse, significant_digits, tick_texts

BUILD = os.environ.get("MANIP_BUILD_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "build"))
DIAG = os.path.join(BUILD, "apps", "diagnose_model")
HIDDEN = os.path.join(BUILD, "apps", "make_hidden_session")
STEMS_SJ = ["diag_prediction", "diag_gains", "diag_xcorr", "diag_fold_vaf"]
STEMS_MANIP = STEMS_SJ + ["diag_residual_time", "diag_impedance"]


def tmpdir(tc):
    d = tempfile.mkdtemp(prefix="diag_plots_")
    if os.environ.get("MANIP_KEEP_TEST_DIRS") != "1":
        tc.addCleanup(shutil.rmtree, d, True)
    return d


# ----------------------------------------------------------------------------- synthetic reports
def _xcorr(scale, sig):
    names = ["velocity (delayed)", "position^2", "sign(velocity)", "time (drift)"]
    return [{"regressor": n, "rho": scale * r, "lag_s": 0.03, "bound95": 0.1, "significant": bool(s)}
            for n, r, s in zip(names, (0.31, -0.12, 0.05, -0.02), sig)]


def _cand(cid, gains, sig, p):
    g = np.asarray(gains, float)
    return {"id": cid, "title": cid, "signature": "", "fold_gain": g.tolist(), "mean_gain": float(g.mean()),
            "se": float(g.std(ddof=1) / np.sqrt(len(g))), "t": 3.0, "p": p, "p_holm": p, "significant": sig,
            "implausible": False, "params": {}}


def report_single_joint():
    rng = np.random.default_rng(1)
    t = np.arange(0, 3.0, 0.001) + 12.0
    y = np.sin(2 * np.pi * 1.3 * t) * 4 - 1.5
    b0 = y + 0.6 * np.sin(2 * np.pi * 0.4 * t)
    b1 = y + 0.1 * rng.standard_normal(len(t))
    return {
        "source": "synthetic.csv", "folds": 5, "misfit": True, "accepted": ["stretch_reflex"],
        "baseline": {"params": [{"name": "K", "unit": "N m/rad", "value": 40.0, "ci95": [38.0, 42.0]}],
                     "heldout_vaf": {"value": 0.81, "ci95": [0.78, 0.84]}, "fold_vaf": [0.80, 0.83, 0.78, 0.85, 0.79]},
        "final": {"params": [{"name": "K", "unit": "N m/rad", "value": 45.0, "ci95": [43.0, 47.0]}],
                  "heldout_vaf": {"value": 0.91, "ci95": [0.89, 0.93]}, "fold_vaf": [0.90, 0.92, 0.88, 0.94, 0.91]},
        "signatures_before": {"xcorr": _xcorr(1.0, (1, 1, 0, 0))},
        "signatures_after": {"xcorr": _xcorr(0.2, (0, 0, 0, 0))},
        "rounds": [{"accepted": "stretch_reflex", "candidates": [
            _cand("stretch_reflex", [0.30, 0.42, 0.35, 0.51, 0.28], True, 1e-4),
            _cand("quadratic_stiffness", [0.05, 0.11, 0.09, 0.07, 0.12], True, 0.003),
            _cand("offset_drift", [0.01, -0.03, 0.02, -0.01, 0.0], False, 0.9),
            {"id": "wrong_inertia", "title": "", "signature": "", "not_applicable": "inertia estimated"}]},
            {"accepted": None, "candidates": []}],
        "traces": {"kind": "single_joint", "unit": "N m", "fold": 2, "extended_model": ["stretch_reflex"],
                   "matches_engine_folds": True, "t_s": t.tolist(), "measured": y.tolist(), "baseline": b0.tolist(),
                   "extended": b1.tolist(), "vaf_baseline": 0.8, "vaf_extended": 0.95},
    }


def report_manipulandum():
    r = report_single_joint()
    r["source"] = "h.lcm"
    r["accepted"] = ["handle_mass"]
    r["rounds"][0]["accepted"] = "handle_mass"
    r["rounds"][0]["candidates"][0]["id"] = "handle_mass"
    names = ["D11", "D12", "D21", "D22", "K11", "K12", "K22"]
    base = [10.0, -7.8, -6.5, 2.1, -106.0, -66.0, 32.0]
    fin = [9.9, -7.7, -6.6, 1.7, 145.0, -75.0, 295.0]
    r["baseline"]["params"] = [{"name": n, "unit": "N s/m" if n[0] == "D" else "N/m", "value": v, "ci95": [v - 2, v + 3]}
                               for n, v in zip(names, base)]
    r["final"]["params"] = [{"name": n, "unit": "N s/m" if n[0] == "D" else "N/m", "value": v, "ci95": [v - 2, v + 3]}
                            for n, v in zip(names, fin)] + [{"name": "handle_extra", "unit": "kg", "value": 0.33, "ci95": [0.28, 0.41]}]

    def dm(D, K, method=None):
        d = {"D_Nspm": D, "K_Npm": K, "D_ci95_lo": [v - 1 for v in D], "D_ci95_hi": [v + 1.5 for v in D],
             "K_ci95_lo": [v - 20 for v in K], "K_ci95_hi": [v + 25 for v in K]}
        if method:
            d["method"] = method
        return d
    r["manipulandum"] = {"default_method": dm([15.1, -8.1, -7.2, 6.3], [-1.1, -95.2, -95.2, 167.1], "pem"),
                         "default_method_extended": dm([11.3, -8.5, -7.5, 4.5], [131.0, -105.4, -105.4, 313.0], "pem"),
                         "default_method_refined": dm([12.0, -8.5, -7.5, 5.0], [105.6, -103.8, -103.8, 284.8])}
    ts = np.arange(0, 0.15, 0.00025)
    n = len(ts)
    wave = [0.03 * np.sin(2 * np.pi * ts / 0.15 * k) for k in (1, 2)]
    r["traces"] = {
        "kind": "manipulandum", "unit": "N", "extended_model": ["handle_mass"], "matches_engine_folds": True,
        "t_after_onset_s": ts.tolist(), "n_trials": 24,
        "mean_residual_before": [w.tolist() for w in wave], "ci95_halfwidth_before": [[0.02] * n, [0.03] * n],
        "mean_residual_after": [(0.3 * w).tolist() for w in wave], "ci95_halfwidth_after": [[0.015] * n, [0.02] * n],
        "trials": [{"trial": k, "log": "h.lcm",
                    "target": [(0.2 * np.sin(40 * ts + k)).tolist(), (0.1 * np.cos(40 * ts + k)).tolist()],
                    "baseline": [(0.15 * np.sin(40 * ts + k)).tolist(), (0.08 * np.cos(40 * ts + k)).tolist()],
                    "extended": [(0.19 * np.sin(40 * ts + k)).tolist(), (0.09 * np.cos(40 * ts + k)).tolist()]}
                   for k in (3, 60, 97)]}
    return r


def by_gid(fig, gid):
    """The error-bar containers whose data line has this gid, else every artist (lines,
    collections, texts) with it."""
    conts, out = [], []
    for ax in fig.axes:
        for c in ax.containers:
            if hasattr(c, "has_xerr") and c.lines[0] is not None and c.lines[0].get_gid() == gid:
                conts.append(c)
        for a in list(ax.lines) + list(ax.collections) + list(ax.texts):
            if a.get_gid() == gid:
                out.append(a)
    return conts or out


def one(tc, fig, gid):
    a = by_gid(fig, gid)
    tc.assertEqual(len(a), 1, "artists with gid %r: %d" % (gid, len(a)))
    return a[0]


def check_numeric_axis(tc, fig, ax, axis):
    """The numeric axis of a figure with a categorical one: label with unit, >= 2 round tick
    labels that parse back to their positions and lie inside the figure."""
    r = draw(fig)
    label = ax.get_xlabel() if axis == "x" else ax.get_ylabel()
    tc.assertRegex(label, UNIT_RE, "%s label without unit" % axis)
    ticks = tick_texts(ax, axis)
    tc.assertGreaterEqual(len(ticks), 2)
    for t in ticks:
        pos = t.get_position()[0 if axis == "x" else 1]
        tc.assertAlmostEqual(parse(t.get_text()), pos, delta=1e-9 * max(1.0, abs(pos)))
        tc.assertLessEqual(significant_digits(t.get_text()), 3, t.get_text())
        bb = t.get_window_extent(r)
        tc.assertTrue(bb.x0 >= fig.bbox.x0 - 1 and bb.x1 <= fig.bbox.x1 + 1, "tick %r outside" % t.get_text())


def category_labels(ax, axis="y"):
    ticks = ax.get_yticks() if axis == "y" else ax.get_xticks()
    labels = ax.get_yticklabels() if axis == "y" else ax.get_xticklabels()
    return {lab.get_text(): float(p) for p, lab in zip(ticks, labels)}


class Figures(unittest.TestCase):
    def test_prediction_single_joint(self):
        rep = report_single_joint()
        fig = DG.fig_prediction(rep)
        ax, axr = fig.axes
        check_axes(self, fig, [ax, axr])
        self.assertEqual(ax.get_ylabel(), "torque [N m]")
        self.assertEqual(axr.get_ylabel(), "residual [N m]")
        self.assertEqual(axr.get_xlabel(), "time in record [s]")
        tr = rep["traces"]
        for key in ("measured", "baseline", "extended"):
            ln = one(self, fig, key)
            np.testing.assert_allclose(ln.get_xdata(), tr["t_s"])
            np.testing.assert_allclose(ln.get_ydata(), tr[key])
        np.testing.assert_allclose(one(self, fig, "residual_extended").get_ydata(),
                                   np.asarray(tr["measured"]) - np.asarray(tr["extended"]))
        b, e = one(self, fig, "baseline"), one(self, fig, "extended")
        self.assertNotEqual(b.get_color(), e.get_color())
        self.assertNotEqual(b.get_linestyle(), e.get_linestyle())
        self.assertIn("fold 3 of 5", fig._suptitle.get_text())
        labels = [t.get_text() for t in ax.get_legend().get_texts()]
        self.assertEqual(labels, ["measured", "baseline (VAF 0.800)", "extended (VAF 0.950)"])

    def test_prediction_without_misfit(self):
        rep = report_single_joint()
        rep["misfit"] = False
        rep["traces"]["extended"] = None
        fig = DG.fig_prediction(rep)
        self.assertEqual(by_gid(fig, "extended"), [])
        one(self, fig, "baseline")

    def test_prediction_manipulandum(self):
        rep = report_manipulandum()
        fig = DG.fig_prediction(rep)
        self.assertEqual(len(fig.axes), 6)
        check_axes(self, fig, fig.axes)
        tr = rep["traces"]
        for i, trl in enumerate(tr["trials"]):
            for a in (0, 1):
                for key in ("target", "baseline", "extended"):
                    ln = one(self, fig, "%s:%d:%d" % (key, i, a))
                    np.testing.assert_allclose(ln.get_ydata(), trl[key][a])
                    np.testing.assert_allclose(ln.get_xdata(), 1e3 * np.asarray(tr["t_after_onset_s"]))
        self.assertEqual(fig.axes[-1].get_xlabel(), "time after onset [ms]")
        self.assertEqual(fig.axes[0].get_title(loc="left"), "trial 3, x1")
        leg = fig.legends[0]
        self.assertEqual([t.get_text() for t in leg.get_texts()],
                         ["target Δu_ext − M_BSP Δẍ", "baseline D Δẋ + K Δx", "extended"])
        r = draw(fig)   # the figure legend does not cover a panel
        lb = leg.get_window_extent(r)
        for ax in fig.axes:
            self.assertFalse(lb.overlaps(ax.get_window_extent(r)), "legend over a panel")

    def test_residual_time(self):
        rep = report_manipulandum()
        fig = DG.fig_residual_time(rep)
        check_axes(self, fig, fig.axes)
        tr = rep["traces"]
        for a, ax in enumerate(fig.axes):
            self.assertEqual(ax.get_ylabel(), "x%d mean residual [N]" % (a + 1))
            for key in ("before", "after"):
                ln = one(self, fig, "mean_%s:%d" % (key, a))
                np.testing.assert_allclose(ln.get_ydata(), tr["mean_residual_" + key][a])
                band = one(self, fig, "band_%s:%d" % (key, a))
                verts = band.get_paths()[0].vertices
                m, h = np.asarray(tr["mean_residual_" + key][a]), np.asarray(tr["ci95_halfwidth_" + key][a])
                self.assertAlmostEqual(verts[:, 1].max(), float(np.max(m + h)), places=9)
                self.assertAlmostEqual(verts[:, 1].min(), float(np.min(m - h)), places=9)
        self.assertEqual(fig.axes[1].get_xlabel(), "time after onset [ms]")

    def test_gains(self):
        rep = report_single_joint()
        fig = DG.fig_gains(rep)
        ax = fig.axes[0]
        check_numeric_axis(self, fig, ax, "x")
        self.assertIn("[%]", ax.get_xlabel())
        cats = category_labels(ax)
        r0 = rep["rounds"][0]
        self.assertEqual(set(cats), {c["id"] for c in r0["candidates"]})   # round 1 only, n/a listed
        for c in r0["candidates"]:
            if "not_applicable" in c:
                self.assertEqual(by_gid(fig, "folds:" + c["id"]), [])
                self.assertIn("not applicable", one(self, fig, "na:" + c["id"]).get_text())
                continue
            pts = one(self, fig, "folds:" + c["id"])
            np.testing.assert_allclose(np.sort(pts.get_xdata()), np.sort(100 * np.asarray(c["fold_gain"])))
            self.assertTrue(np.all(np.abs(pts.get_ydata() - cats[c["id"]]) < 0.2))   # on the candidate's row
            eb = one(self, fig, "mean:" + c["id"])
            x, y = eb.lines[0].get_data()
            self.assertAlmostEqual(float(x[0]), 100 * c["mean_gain"])
            self.assertAlmostEqual(float(y[0]), cats[c["id"]])
            seg = eb.lines[2][0].get_segments()[0]
            self.assertAlmostEqual(seg[1][0] - seg[0][0], 2 * 100 * c["se"])
            tag = one(self, fig, "tag:" + c["id"]).get_text()
            self.assertEqual(tag.startswith("*"), c["significant"])
            self.assertEqual("ACCEPTED" in tag, c["id"] == r0["accepted"])
            self.assertEqual(eb.get_label() == "accepted", c["id"] == r0["accepted"])
        acc = one(self, fig, "mean:" + r0["accepted"])
        self.assertEqual(acc.lines[0].get_color(), DG.ACCEPTED_COLOR)
        self.assertEqual(acc.lines[0].get_marker(), "D")
        leg = [t.get_text() for t in ax.get_legend().get_texts()]
        self.assertIn("accepted", leg)
        self.assertIn("significant (Holm)", leg)

    def test_xcorr(self):
        rep = report_single_joint()
        fig = DG.fig_xcorr(rep)
        ax = fig.axes[0]
        check_numeric_axis(self, fig, ax, "x")
        cats = category_labels(ax)
        for key in ("before", "after"):
            xc = rep["signatures_" + key]["xcorr"]
            bars = [p for p in ax.patches if p.get_gid() == "rho_" + key]
            self.assertEqual(len(bars), len(xc))
            for b, c in zip(bars, xc):
                self.assertAlmostEqual(b.get_width(), c["rho"])
                self.assertAlmostEqual(b.get_y() + b.get_height() / 2, cats[c["regressor"]], delta=0.3)
            bl = one(self, fig, "bound_" + key)
            np.testing.assert_allclose(np.abs(bl.get_xdata()), [c["bound95"] for c in xc] * 2)
            for c in xc:
                self.assertEqual(len(by_gid(fig, "significant_%s:%s" % (key, c["regressor"]))), int(c["significant"]))
        lo, hi = ax.get_xlim()
        self.assertLess(lo, -0.31)
        self.assertGreater(hi, 0.31)

    def test_fold_vaf(self):
        rep = report_single_joint()
        fig = DG.fig_fold_vaf(rep)
        ax = fig.axes[0]
        check_axes(self, fig, [ax])
        self.assertEqual(ax.get_ylabel(), "held-out VAF [%]")
        for key, src in (("before", rep["baseline"]), ("after", rep["final"])):
            ln = one(self, fig, "fold_vaf_" + key)
            np.testing.assert_allclose(ln.get_ydata(), 100 * np.asarray(src["fold_vaf"]))
            np.testing.assert_allclose(ln.get_xdata(), np.arange(1, 6))
            self.assertAlmostEqual(float(one(self, fig, "pooled_vaf_" + key).get_ydata()[0]), 100 * src["heldout_vaf"]["value"])
        xt = [parse(t.get_text()) for t in tick_texts(ax, "x")]
        self.assertTrue(all(v == int(v) for v in xt), xt)   # folds are integers
        b, a = one(self, fig, "fold_vaf_before"), one(self, fig, "fold_vaf_after")
        self.assertNotEqual(b.get_linestyle(), a.get_linestyle())
        self.assertNotEqual(b.get_marker(), a.get_marker())

    def test_impedance(self):
        rep = report_manipulandum()
        fig = DG.fig_impedance(rep)
        axd, axk = fig.axes
        self.assertEqual(axd.get_ylabel(), "damping [N s/m]")
        self.assertEqual(axk.get_ylabel(), "stiffness [N/m]")
        for ax in (axd, axk):
            check_numeric_axis(self, fig, ax, "y")
        self.assertEqual(list(category_labels(axd, "x")), ["D11", "D12", "D21", "D22"])
        self.assertEqual(list(category_labels(axk, "x")), ["K11", "K12", "K22"])
        rows = DG.impedance_rows(rep)
        self.assertEqual([r["label"] for r in rows], ["equation error, baseline", "equation error, extended",
                                                     "pem, no extension", "pem, with extension", "pem, extension refined"])
        base = {p["name"]: p for p in rep["baseline"]["params"]}
        pem_ext = rep["manipulandum"]["default_method_extended"]
        for which, ax, elems in (("D", axd, DG.ELEMENTS_D), ("K", axk, DG.ELEMENTS_K)):
            eb = one(self, fig, "%s:equation error, baseline" % which)
            y = eb.lines[0].get_ydata()
            np.testing.assert_allclose(y, [base[e]["value"] for e in elems])
            segs = eb.lines[2][0].get_segments()
            for s, e in zip(segs, elems):
                self.assertAlmostEqual(s[0][1], base[e]["ci95"][0])
                self.assertAlmostEqual(s[1][1], base[e]["ci95"][1])
            eb = one(self, fig, "%s:pem, with extension" % which)
            key = "D_Nspm" if which == "D" else "K_Npm"
            np.testing.assert_allclose(eb.lines[0].get_ydata(), [pem_ext[key][DG.ELEMENT_INDEX[e]] for e in elems])
            # each estimate beside its element's tick
            cats = category_labels(ax, "x")
            for e, x in zip(elems, eb.lines[0].get_xdata()):
                self.assertLess(abs(x - cats[e]), 0.5)

    def test_figures_driver_and_cli(self):
        d = tmpdir(self)
        for rep, stems in ((report_single_joint(), STEMS_SJ), (report_manipulandum(), STEMS_MANIP)):
            notes = []
            figs = DG.figures(rep, notes)
            self.assertEqual(set(figs), set(stems))
            self.assertEqual(notes, [])
        p = os.path.join(d, "r.json")
        with open(p, "w") as f:
            json.dump(report_manipulandum(), f)
        out = os.path.join(d, "out")
        quiet = contextlib.redirect_stdout(io.StringIO())
        with quiet:
            self.assertEqual(DG.main([p, "-o", out, "--format", "png,svg"]), 0)
        self.assertEqual(sorted(os.listdir(out)),
                         sorted(["diagnosis.json"] + [s + e for s in STEMS_MANIP for e in (".png", ".svg")]))
        with open(os.path.join(out, "diag_impedance.svg")) as f:
            self.assertIn("stiffness [N/m]", f.read())   # text kept as text
        bad = os.path.join(d, "bad.json")
        with open(bad, "w") as f:
            f.write("[1, 2]")
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            self.assertEqual(DG.main([bad, "-o", os.path.join(d, "o2")]), 2)
        self.assertIn("not a diagnose_model report", err.getvalue())
        old = report_single_joint()
        del old["traces"]
        with open(p, "w") as f:
            json.dump(old, f)
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            self.assertEqual(DG.main([p, "-o", os.path.join(d, "o3")]), 1)   # named on stderr, the others drawn
        self.assertIn("diag_prediction not drawn", err.getvalue())
        self.assertTrue(os.path.exists(os.path.join(d, "o3", "diag_gains.png")))


# ----------------------------------------------------------------------------- the app
def write_single_joint_csv(path, seconds=16.0, dt=0.002, seed=4):
    """Position: smoothed random steps (0.03 rad); torque = I θ̈ + B θ̇ + K θ + a delayed
    rectified-velocity reflex through a low pass (so the search has something to find) + noise."""
    rng = np.random.default_rng(seed)
    n = int(round(seconds / dt))
    steps = np.repeat(rng.uniform(-0.03, 0.03, n // 100 + 1), 100)[:n]
    pos = steps.copy()
    a = np.exp(-2 * np.pi * 8 * dt)
    for _ in range(2):   # 2nd-order low pass
        for i in range(1, n):
            pos[i] = a * pos[i - 1] + (1 - a) * pos[i]
    vel = np.gradient(pos, dt)
    acc = np.gradient(vel, dt)
    d = int(0.04 / dt)
    refl = np.concatenate([np.zeros(d), np.maximum(vel[:-d], 0)])
    b = np.exp(-2 * np.pi * 6 * dt)
    for i in range(1, n):
        refl[i] = b * refl[i - 1] + (1 - b) * refl[i]
    tq = 0.02 * acc + 0.4 * vel + 40 * pos + 6.0 * refl + 0.02 * rng.standard_normal(n)
    with open(path, "w") as f:
        f.write("# dt=%g; synthetic record of tests/test_diagnosis_plots.py\n" % dt)
        for p, q in zip(pos, tq):
            f.write("%.9g,%.9g\n" % (p, q))


def snapshot(d):
    out = {}
    for root, _, files in os.walk(d):
        for fn in files:
            p = os.path.join(root, fn)
            st = os.stat(p)
            with open(p, "rb") as f:
                out[os.path.relpath(p, d)] = (st.st_mtime_ns, hashlib.sha256(f.read()).hexdigest())
    return out


class App(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        for p in (DIAG, HIDDEN):
            if not os.path.exists(p):
                raise AssertionError("%s not built (cmake --build build --target diagnose_model make_hidden_session)" % p)

    def run_app(self, args, rc=0, env=None):
        r = subprocess.run([DIAG, "-q"] + args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=120,
                           env=dict(os.environ, **(env or {})))
        self.assertEqual(r.returncode, rc, r.stderr[-3000:])
        return r

    def check_dir(self, out, stems, js):
        files = set(os.listdir(out))
        self.assertEqual(files, {"diagnosis.json"} | {s + e for s in stems for e in (".png", ".pdf")})
        for s in stems:
            with open(os.path.join(out, s + ".png"), "rb") as f:
                self.assertEqual(f.read(8), b"\x89PNG\r\n\x1a\n")
            with open(os.path.join(out, s + ".pdf"), "rb") as f:
                self.assertEqual(f.read(5), b"%PDF-")
        with open(os.path.join(out, "diagnosis.json")) as f:
            drawn = json.load(f)
        with open(js) as f:
            written = json.load(f)
        drawn.pop("seconds", None)
        written.pop("seconds", None)
        self.assertEqual(drawn, written)   # the figures come from the numbers --json writes
        tr = written["traces"]
        self.assertTrue(tr["matches_engine_folds"])   # the traces' held-out predictions are the engine's
        self.assertEqual(len(written["final"]["fold_vaf"]), written["folds"])
        # the figures drawn from that JSON show its numbers
        figs = DG.figures(written)
        r0 = written["rounds"][0]
        for c in r0["candidates"]:
            if "fold_gain" in c:
                pts = one(self, figs["diag_gains"], "folds:" + c["id"])
                np.testing.assert_allclose(np.sort(pts.get_xdata()), np.sort(100 * np.asarray(c["fold_gain"])))
        if r0["accepted"]:
            self.assertEqual(one(self, figs["diag_gains"], "mean:" + r0["accepted"]).get_label(), "accepted")
        np.testing.assert_allclose(one(self, figs["diag_fold_vaf"], "fold_vaf_before").get_ydata(),
                                   100 * np.asarray(written["baseline"]["fold_vaf"]))
        return written

    def test_single_joint(self):
        d = tmpdir(self)
        csv = os.path.join(d, "rec.csv")
        write_single_joint_csv(csv)
        out, js = os.path.join(d, "plots"), os.path.join(d, "r.json")
        self.run_app(["--single-joint", csv, "--folds", "5", "--bootstrap", "50", "--json", js, "--plots", out])
        rep = self.check_dir(out, STEMS_SJ, js)
        tr = rep["traces"]
        self.assertEqual(tr["kind"], "single_joint")
        self.assertLessEqual(tr["t_s"][-1] - tr["t_s"][0], 3.0)
        self.assertEqual(len(tr["measured"]), len(tr["t_s"]))
        self.assertIn("stretch_reflex", rep["accepted"])
        # an existing, non-empty DIR without --force: exit 6, one line, nothing read, DIR untouched
        before = snapshot(out)
        r = self.run_app(["--single-joint", csv, "--folds", "5", "--plots", out], rc=6)
        self.assertEqual(len(r.stderr.strip().splitlines()), 1, r.stderr)
        self.assertIn("--plots %s: exists and is not empty (pass --force" % out, r.stderr)
        self.assertEqual(r.stdout, "")   # refused before any input is read
        self.assertEqual(snapshot(out), before)
        # a file as DIR: exit 6 too
        r = self.run_app(["--single-joint", csv, "--folds", "5", "--plots", csv], rc=6)
        self.assertIn("is not a directory", r.stderr)
        # --force redraws into it
        self.run_app(["--single-joint", csv, "--folds", "5", "--bootstrap", "50", "--plots", out, "--force"])
        self.assertEqual(set(snapshot(out)), set(before))
        self.assertEqual([f for f in os.listdir(d) if f.startswith(".plots.partial")], [])
        # no usable Python: the report still printed, then exit 6 with one line; no DIR left behind
        nopy = os.path.join(d, "nopy")
        r = self.run_app(["--single-joint", csv, "--folds", "5", "--bootstrap", "50", "--plots", nopy], rc=6,
                         env={"MANIP_PYTHON": "/nonexistent/python"})
        self.assertIn("Result:", r.stdout)
        self.assertEqual(r.stderr.strip().splitlines(),
                         ["diagnose_model: --plots %s: not written: Python interpreter '/nonexistent/python' cannot be run "
                          "(set MANIP_PYTHON or run scripts/setup.sh)" % nopy])
        self.assertFalse(os.path.exists(nopy))

    def test_manipulandum(self):
        d = tmpdir(self)
        log = os.path.join(d, "h.lcm")
        r = subprocess.run([HIDDEN, "-q", "--out", log, "--hidden", "handle:0.3", "--hidden-seed", "1", "--movements", "60"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=120)
        self.assertEqual(r.returncode, 0, r.stderr)
        out, js = os.path.join(d, "plots"), os.path.join(d, "h.json")
        # Three mechanisms (diagnose_model --mechanisms): the handle, the inertia that shares its
        # signature and the delay; a third of the library's likelihood fits.
        mech = "handle_mass,wrong_segment_inertia,actuation_delay"
        self.run_app([log, "--folds", "5", "--bootstrap", "50", "--mechanisms", mech, "--json", js, "--plots", out])
        rep = self.check_dir(out, STEMS_MANIP, js)
        self.assertIn("library restricted to handle_mass, wrong_segment_inertia, actuation_delay (--mechanisms)",
                      rep["preprocessing"])
        self.assertEqual({c["id"] for c in rep["rounds"][0]["candidates"]}, set(mech.split(",")))
        self.assertEqual(rep["conclusion"]["named"][:1], ["handle_mass"])
        tr = rep["traces"]
        self.assertEqual(tr["kind"], "manipulandum")
        self.assertEqual(tr["n_trials"], rep["manipulandum"]["used"])
        self.assertAlmostEqual(tr["t_after_onset_s"][-1], rep["manipulandum"]["t_est_s"], delta=0.002)
        for key in ("before", "after") if rep["misfit"] else ("before",):
            self.assertEqual(len(tr["mean_residual_" + key]), 2)
            self.assertEqual(len(tr["mean_residual_" + key][0]), len(tr["t_after_onset_s"]))
        self.assertEqual(len(tr["trials"]), 3)
        before = snapshot(out)
        r = self.run_app([log, "--folds", "5", "--plots", out], rc=6)
        self.assertEqual(len(r.stderr.strip().splitlines()), 1, r.stderr)
        self.assertEqual(snapshot(out), before)


if __name__ == "__main__":
    unittest.main()
