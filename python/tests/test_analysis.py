import math
import statistics
import unittest

import numpy as np

from manipplot import analysis as A
from manipplot.io import parse_results

from .util import results_doc, summary


class Directional(unittest.TestCase):
    def test_quadratic_form(self):
        K = np.array([[110.0, -106.0], [-90.0, 314.0]])
        for phi in (0, 30, 90, 150, 210, 330):
            u = np.array([math.cos(math.radians(phi)), math.sin(math.radians(phi))])
            self.assertAlmostEqual(float(A.quad(K, phi)), float(u @ K @ u), places=9)
        # u and -u push along the same line: same directional value.
        self.assertAlmostEqual(float(A.quad(K, 30)), float(A.quad(K, 210)), places=9)

    def test_covariance_interval_is_what_one_direction_determines(self):
        # Full 2x2 poorly determined (large, strongly correlated element errors), directional value well determined.
        phi = 30.0
        g = A.quad_gradient(phi)
        rng = np.random.default_rng(1)
        B = rng.normal(size=(4, 4))
        # Covariance large along directions orthogonal to g, small along g.
        P = np.eye(4) - np.outer(g, g) / (g @ g)
        C = 1e6 * P @ B @ B.T @ P + 4.0 * np.outer(g, g) / (g @ g) ** 2
        d = summary("pem", "angle 30", [10, -8, -8, 7], [110, -106, -106, 10067], rel_se=0.3, ident=False, n=3,
                    angle=30)
        d["K_cov"] = C.ravel().tolist()
        s = parse_results({"sessions": [{"summaries": [d]}]}).sessions[0].summaries[0]
        r = A.directional(s, "K")
        K = np.array(d["K_Npm"]).reshape(2, 2)
        self.assertAlmostEqual(r.value, float(A.quad(K, phi)), places=6)
        se = math.sqrt(g @ C @ g)
        self.assertAlmostEqual(se, 2.0, places=4)
        self.assertAlmostEqual(r.hi - r.value, 2.0 * se, places=4)   # util's t = 2.0 read back from the JSON
        self.assertEqual(r.interval, "covariance (95 %)")
        self.assertFalse(r.identifiable)
        # Without the covariance: the conservative bound sum |g_i| se_i, never narrower.
        del d["K_cov"]
        s2 = parse_results({"sessions": [{"summaries": [d]}]}).sessions[0].summaries[0]
        r2 = A.directional(s2, "K")
        bound = float(np.abs(g) @ np.abs(np.array(d["K_spread"])))
        self.assertAlmostEqual(r2.hi - r2.value, 2.0 * bound, places=6)
        self.assertIn("conservative", r2.interval)
        self.assertGreater(r2.hi - r2.lo, r.hi - r.lo)

    def test_per_trial_interval(self):
        d = summary("oe-trial", "angle 60", [10, -8, -8, 7], [110, -106, -106, 314], angle=60, n=3, kind="per-trial")
        Ks = [[100, -100, -100, 300], [120, -110, -110, 330], [115, -90, -90, 290]]
        trials = [{"trial": i, "angle_deg": 60.0, "method": "oe-trial", "D_Nspm": [10, -8, -8, 7], "K_Npm": k}
                  for i, k in enumerate(Ks)]
        trials.append({"trial": 9, "angle_deg": 240.0, "method": "oe-trial", "K_Npm": [1e6, 0, 0, 1e6],
                       "D_Nspm": [0, 0, 0, 0]})   # other angle: must not count
        s = parse_results({"sessions": [{"summaries": [d], "trials": trials}]}).sessions[0]
        r = A.directional(s.summaries[0], "K", s.trials)
        v = [float(A.quad(np.array(k, float).reshape(2, 2), 60)) for k in Ks]
        self.assertAlmostEqual(r.value, statistics.mean(v), places=9)
        h = 4.302652729911275 * statistics.stdev(v) / math.sqrt(3)   # t(0.975, 2)
        self.assertAlmostEqual(r.hi - r.value, h, places=6)

    def test_angle_from_group_string_or_number(self):
        doc = {"sessions": [{"summaries": [summary("pem", "angle 120", [1, 0, 0, 1], [1, 0, 0, 1]),
                                           summary("pem", "per-angle", [1, 0, 0, 1], [1, 0, 0, 1], angle=150.0),
                                           summary("pem", "session", [1, 0, 0, 1], [1, 0, 0, 1])]}]}
        s = parse_results(doc).sessions[0]
        self.assertEqual([x.angle_deg for x in s.per_angle("pem")], [120.0, 150.0])
        # a separate typed per-angle list (a possible later layout) is read too
        x = summary("pem", "ignored", [1, 0, 0, 1], [2, 0, 0, 2], angle=30.0)
        del x["group"]
        doc["sessions"][0]["per_angle"] = [x]
        s = parse_results(doc).sessions[0]
        self.assertEqual([x.angle_deg for x in s.per_angle("pem")], [30.0, 120.0, 150.0])
        self.assertEqual(s.per_angle("pem")[0].group, "angle 30")


class Nrmse(unittest.TestCase):
    def test_definition(self):
        fs = 1000.0
        t = np.arange(0, 0.151, 1 / fs)
        tru = np.column_stack([np.sin(20 * t), 2 * t])
        est = tru + np.column_stack([0.01 * np.ones_like(t), 0.02 * t])
        c = A.nrmse_one(est, tru, fs, np.array([0.05, 0.15]), 0.15)
        peak = np.max(np.abs(tru), axis=0)
        self.assertAlmostEqual(c[1, 0], 0.01 / peak[0], places=12)
        k = int(round(0.05 * fs)) + 1
        self.assertAlmostEqual(c[0, 1], math.sqrt(np.mean((0.02 * t[:k]) ** 2)) / peak[1], places=12)


class Psd(unittest.TestCase):
    def test_auto_cutoff_and_reference(self):
        f = np.linspace(0, 10, 101)
        pu = np.exp(-((f - 0.6) ** 2))
        pu[0] = 0.0
        pp = pu * np.where(f > 1.05, 10.0, 1.0)
        p = A.psd_stats(f, pu, pp, 10, 5, 3.0)
        self.assertAlmostEqual(p.peak_unperturbed_hz, 0.6)
        self.assertAlmostEqual(p.cutoff_auto_hz, 1.1)
        self.assertAlmostEqual(float(p.db(p.p_unperturbed[6])), 0.0)


class Group(unittest.TestCase):
    def test_mean_std_and_refusal(self):
        docs = [results_doc("P%d" % i, D=[10 + i, -8, -8.5, 6.7 + i / 10], K=[110 * i, -106, -106, 300 + 7 * i])
                for i in range(1, 6)]
        ss = [parse_results(d).sessions[0] for d in docs]
        g = A.group_table(ss, "pem")
        self.assertEqual(g.n, 5)
        for n, i in (("D11", 0), ("K11", 0), ("K22", 3), ("D22", 3)):
            key = "D_Nspm" if n[0] == "D" else "K_Npm"
            vals = [d["sessions"][0]["summaries"][0][key][i] for d in docs]
            self.assertAlmostEqual(g.mean[n], statistics.mean(vals), places=9)
            self.assertAlmostEqual(g.std[n], statistics.stdev(vals), places=9)
        other = parse_results(results_doc("P9", settings={"t_est_s": 0.1})).sessions[0]
        with self.assertRaises(A.GroupError) as cm:
            A.check_same_configuration(ss + [other])
        self.assertIn("t_est_s", str(cm.exception))
        self.assertEqual([len(x) for x in A.split_by_settings(ss + [other])], [5, 1])


if __name__ == "__main__":
    unittest.main()
