import math
import os
import tempfile
import unittest

import numpy as np
from matplotlib.lines import Line2D

from manipplot import analysis as A
from manipplot import figures as F
from manipplot.io import parse_results

from .figcheck import check_axes, draw, legend_entries, parse, tick_texts
from .util import results_doc


def synthetic_signals(n=601, fs=4000.0):
    t = np.arange(n) / fs
    env = np.sin(np.pi * np.clip(t / 0.15, 0, 1)) ** 2
    up = np.column_stack([15 * 0.866 * env, 15 * 0.5 * env])
    dx = np.column_stack([-0.0061 * (t / 0.15) ** 3, 0.0059 * (t / 0.15) ** 3])   # x1 negative: sign must survive
    dxd = np.gradient(dx, t, axis=0)
    dxdd = np.gradient(dxd, t, axis=0)
    du = up - 5.6 * dxdd - 15 * dxd
    return {"t_s": t, "dx": dx, "dxd": dxd, "dxdd": dxdd, "du_ext": du, "u_pert": up, "dx_true": dx * 1.02}


class Fig3(unittest.TestCase):
    def test_psd(self):
        f = np.arange(0, 2001) * 4000 / 65536
        pu = 1e3 * np.exp(-((f - 0.61) / 0.4) ** 2) + 1e-2
        pp = pu * np.where(f > 1.0, 30.0, 1.0)
        p = A.psd_stats(f, pu, pp, 14, 10, 3.0)
        fig = F.fig_psd(p, cutoff_used_hz=1.0)
        ax = fig.axes[0]
        check_axes(self, fig, [ax])
        self.assertIn("[dB re unpert. peak]", ax.get_ylabel())
        self.assertIn("frequency [Hz]", ax.get_xlabel())
        self.assertIn("0 dB = %.3g (m/s³)²/Hz" % p.reference, ax.get_title(loc="left"))
        labels = {t: h for t, h in legend_entries(fig)}
        self.assertIn("unperturbed (n = 14)", labels)
        self.assertIn("perturbed (n = 10)", labels)
        self.assertIn("unperturbed + 3 dB (threshold)", labels)
        self.assertTrue(any(k.startswith("cut-off used f_c,HP = 1 Hz") for k in labels))
        self.assertTrue(any(k.startswith("auto cut-off") for k in labels))
        for h in labels.values():
            self.assertIsInstance(h, Line2D)   # a line/marker sample, not coloured text
        lines = {l.get_label(): l for l in ax.get_lines()}
        cut = next(l for k, l in lines.items() if k.startswith("cut-off used"))
        self.assertTrue(np.allclose(cut.get_xdata(), 1.0))
        u = lines["unperturbed (n = 14)"].get_ydata()
        thr = lines["unperturbed + 3 dB (threshold)"].get_ydata()
        self.assertTrue(np.allclose(thr - u, 3.0))
        self.assertAlmostEqual(float(np.max(u)), 0.0, places=6)   # dB re unperturbed peak
        xt = [parse(t.get_text()) for t in tick_texts(ax, "x")]
        self.assertIn(1.0, xt)
        self.assertIn(10.0, xt)


class Fig4(unittest.TestCase):
    def test_nrmse(self):
        dt = np.linspace(0.005, 0.15, 30)
        mean = {s: np.column_stack([k * dt / 0.15, 1.3 * k * dt / 0.15]) for s, k in
                zip(A.SIGNALS, (0.02, 0.03, 0.05, 0.12))}
        std = {s: 0.2 * m for s, m in mean.items()}
        fig = F.fig_nrmse(A.Nrmse(dt, mean, std, 9))
        axs = fig.axes
        self.assertEqual(len(axs), 4)
        check_axes(self, fig, axs)
        bounds = {}
        for ax, s in zip(axs, A.SIGNALS):
            self.assertEqual(ax.get_ylabel(), "NRMSE [%]")
            ls = {l.get_label(): l for l in ax.get_lines()}
            bounds[s] = float(ls["paper bound"].get_ydata()[0])
            x1, x2 = ls["x1"], ls["x2"]
            self.assertNotEqual(x1.get_color(), x2.get_color())
            self.assertNotEqual(x1.get_linestyle(), x2.get_linestyle())
            self.assertTrue(np.allclose(x1.get_ydata(), 100 * mean[s][:, 0]))
            self.assertTrue(np.allclose(x2.get_xdata(), dt * 1e3))
            self.assertGreater(ax.get_ylim()[1], bounds[s])   # the bound is inside the plot
        self.assertEqual(bounds, {"dx": 5.0, "dxd": 5.0, "dxdd": 7.5, "du_ext": 15.0})
        self.assertEqual(axs[2].get_xlabel(), "Δt [ms]")
        self.assertEqual([parse(t.get_text()) for t in tick_texts(axs[2], "x")], [0, 50, 100, 150])
        self.assertEqual({t for t, _ in legend_entries(fig)}, {"x1", "x2", "paper bound"})


class Fig5(unittest.TestCase):
    def test_variational_panels(self):
        sig = synthetic_signals()
        tru = {"dx": sig["dx"] * 1.01, "dxd": sig["dxd"], "dxdd": sig["dxdd"], "du_ext": sig["du_ext"]}
        fig = F.fig_variational(sig, tru, trial=7, angle_deg=30.0)
        axs = fig.axes
        self.assertEqual([a.get_ylabel() for a in axs],
                         ["u_pert [N]", "Δu_ext [N]", "Δẍ [m/s²]", "Δẋ [mm/s]", "Δx [mm]"])
        check_axes(self, fig, axs)
        self.assertEqual(axs[-1].get_xlabel(), "time after onset [ms]")
        # Δx in mm, both axes, truth drawn; u_pert in N.
        dx_lines = {l.get_label(): l for l in axs[4].get_lines()}
        self.assertTrue(np.allclose(dx_lines["x1"].get_ydata(), 1e3 * sig["dx"][:, 0]))
        self.assertTrue(np.allclose(dx_lines["truth"].get_ydata(), 1e3 * tru["dx"][:, 0]))
        self.assertAlmostEqual(float(np.max(axs[0].get_lines()[0].get_ydata())), 15 * 0.866, places=3)
        # negative tick labels keep their sign
        neg = [t.get_text() for t in tick_texts(axs[4], "y") if t.get_position()[1] < 0]
        self.assertTrue(neg and all(t.startswith("-") for t in neg), neg)
        for ax in axs:   # each signal in its own panel, with a non-degenerate range
            y = np.concatenate([l.get_ydata() for l in ax.get_lines() if l.get_label() in ("x1", "x2")])
            lo, hi = ax.get_ylim()
            self.assertGreater(np.ptp(y), 0.3 * (hi - lo))
        self.assertIn("trial 7", fig._suptitle.get_text())


class Directional(unittest.TestCase):
    def test_directional_figure(self):
        s = parse_results(results_doc()).sessions[0]
        fig = F.fig_directional(s, "pem")
        axd, axk = fig.axes
        check_axes(self, fig, [axd, axk], max_digits=3)
        self.assertEqual(axd.get_ylabel(), "uᵀDu [N s/m]")
        self.assertEqual(axk.get_ylabel(), "uᵀKu [N/m]")
        self.assertEqual(axk.get_xlabel(), "perturbation angle φ [deg]")
        self.assertEqual([parse(t.get_text()) for t in tick_texts(axk, "x")], [0, 90, 180, 270, 360])
        sess = s.summary("pem")
        lines = {l.get_label(): l for l in axk.get_lines()}
        ref = lines["session estimate (pem)"]
        self.assertTrue(np.allclose(ref.get_ydata(), A.quad(sess.K, ref.get_xdata())))
        self.assertIn("truth (simulated)", lines)
        # per-angle points with error bars (flagged per-angle 2x2 fits drawn hollow): D per angle equals
        # the session's D here, so every point is in range.
        cont = [c for c in axd.containers if c.get_label() == "per angle, flagged fit"]
        self.assertEqual(len(cont), 1)
        x, y = cont[0].lines[0].get_data()
        self.assertEqual(list(x), [30, 60, 120, 150, 210, 240, 300, 330])
        np.testing.assert_allclose(y, A.quad(sess.D, x))
        self.assertEqual(cont[0].lines[0].get_markerfacecolor(), "none")
        seg = cont[0].lines[2][0].get_segments()
        self.assertEqual(len(seg), 8)
        self.assertTrue(all(sg[0][1] < yy < sg[1][1] for sg, yy in zip(seg, y)))
        # K per angle has K22 = 10067 N/m (the case): far above the session curve, drawn off scale
        # at the top edge instead of squashing the session estimate and the truth into a flat line.
        off = [l for l in axk.get_lines() if l.get_label() == "per angle, off scale (see table)"]
        self.assertEqual(len(off), 1)
        self.assertEqual(len(off[0].get_xdata()), 8)
        self.assertTrue(np.allclose(off[0].get_ydata(), axk.get_ylim()[1]))
        self.assertGreater(np.ptp(ref.get_ydata()), 0.2 * (axk.get_ylim()[1] - axk.get_ylim()[0]))
        draw(fig)


class Table1(unittest.TestCase):
    def test_table_figure_and_save(self):
        cells = {n: "-%d.000 [-1.000e+05, 1.000e+05]" % i for i, n in enumerate(A.ELEMENT_NAMES)}
        fig = F.fig_table1("P1, pem", cells)
        texts = {t.get_gid(): t for t in fig.axes[0].texts}
        self.assertEqual(texts["header:D"].get_text(), "Damping D [N s/m]")
        self.assertEqual(texts["header:K"].get_text(), "Stiffness K [N/m]")
        for n in A.ELEMENT_NAMES:
            self.assertEqual(texts["cell:" + n].get_text(), cells[n])
        # Layout like the paper: D block left of K block, row 1 above row 2, column 1 left of column 2.
        pos = {n: texts["cell:" + n].get_position() for n in A.ELEMENT_NAMES}
        self.assertLess(pos["D12"][0], pos["K11"][0])
        self.assertGreater(pos["K12"][1], pos["K22"][1])
        self.assertLess(pos["K21"][0], pos["K22"][0])
        r = draw(fig)
        boxes = [texts["cell:" + n].get_window_extent(r) for n in A.ELEMENT_NAMES]
        for i in range(len(boxes)):
            self.assertTrue(fig.bbox.x0 <= boxes[i].x0 and boxes[i].x1 <= fig.bbox.x1)
            for j in range(i + 1, len(boxes)):
                self.assertFalse(boxes[i].overlaps(boxes[j]), "cells overlap")
        d = tempfile.mkdtemp()
        paths = F.save(fig, os.path.join(d, "t"), ("png", "pdf", "svg"))
        self.assertEqual([os.path.splitext(p)[1] for p in paths], [".png", ".pdf", ".svg"])
        with open(paths[0], "rb") as f:
            self.assertEqual(f.read(8), b"\x89PNG\r\n\x1a\n")
        with open(paths[1], "rb") as f:
            self.assertEqual(f.read(5), b"%PDF-")
        with open(paths[2]) as f:
            self.assertIn("Stiffness K [N/m]", f.read())


if __name__ == "__main__":
    unittest.main()
