"""Five simulated participants (different seeds and people) -> Table-1 style group table.

The group mean and std are checked against values computed here independently
(stdlib json + statistics, not manipplot) from each participant's JSON."""
import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import unittest

from . import fixtures as FX

ELEMS = ["D11", "D12", "D21", "D22", "K11", "K12", "K21", "K22"]


def read_csv(p):
    with open(p, newline="") as f:
        return list(csv.DictReader(f))


def independent(method):
    per = {}
    for p in FX.GROUP_JSON:
        with open(p) as f:
            doc = json.load(f)
        (s,) = doc["sessions"]
        summ = next(x for x in s["summaries"] if x["method"] == method and x["group"] == "session")
        vals = summ["D_Nspm"] + summ["K_Npm"]
        per[s["log"]] = dict(zip(ELEMS, vals))
    return per


class GroupTable(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        FX.require(*FX.GROUP_JSON)
        cls.d = tempfile.mkdtemp(prefix="manipplot_group_")
        cls.csv = os.path.join(cls.d, "g.csv")
        cls.json = os.path.join(cls.d, "g.json")
        cls.proc = subprocess.run([sys.executable, "-m", "manipplot.group"] + FX.GROUP_JSON +
                                 ["--method", "pem", "--method", "oe", "--csv", cls.csv, "--json", cls.json],
                                 capture_output=True, text=True)

    def test_cli_ok(self):
        self.assertEqual(self.proc.returncode, 0, self.proc.stderr)
        self.assertIn("mean (std), n = 5", self.proc.stdout)
        self.assertIn("method pem [default, recommended]", self.proc.stdout)

    def test_mean_std_equal_independent_values(self):
        rows = read_csv(self.csv)
        for method in ("pem", "oe"):
            per = independent(method)
            self.assertEqual(len(per), 5)
            for e in ELEMS:
                vals = [per[p][e] for p in per]
                mean = next(float(r["value_si"]) for r in rows
                            if r["method"] == method and r["parameter"] == e and r["statistic"] == "mean")
                std = next(float(r["value_si"]) for r in rows
                           if r["method"] == method and r["parameter"] == e and r["statistic"] == "std")
                self.assertAlmostEqual(mean, statistics.mean(vals), delta=1e-9 * max(1, abs(mean)))
                self.assertAlmostEqual(std, statistics.stdev(vals), delta=1e-9 * max(1, abs(std)))
                # participants really differ (different people and seeds), so the std is informative
                self.assertGreater(statistics.stdev(vals), 0.0)
                # each participant's row carries its estimate and interval
                prow = [r for r in rows if r["method"] == method and r["parameter"] == e and r["level"] == "participant"]
                self.assertEqual(sorted(r["log"] for r in prow), sorted(per))
                self.assertEqual(len({r["participant_id"] for r in prow}), 5)   # unique labels
                for r in prow:
                    self.assertAlmostEqual(float(r["value_si"]), per[r["log"]][e], delta=1e-9 * max(1, abs(per[r["log"]][e])))
                    self.assertLess(float(r["ci95_lo_si"]), float(r["ci95_hi_si"]))
        # K of the stiff participants is larger: the table separates people
        per = independent("pem")
        k11 = {p: v["K11"] for p, v in per.items()}
        self.assertGreater(statistics.stdev(k11.values()), 0.05 * abs(statistics.mean(k11.values())))

    def test_csv_typed_and_units(self):
        rows = read_csv(self.csv)
        self.assertEqual(len(rows), 2 * 8 * (5 + 2))
        for r in rows:
            self.assertIn(r["unit"], ("N s/m", "N/m"))
            self.assertEqual(r["unit"], "N s/m" if r["parameter"].startswith("D") else "N/m")
            float(r["value_si"])
            int(r["row"]), int(r["col"]), int(r["n_participants"])
            self.assertIn(r["is_default"], ("true", "false"))
            self.assertIn(r["is_biased"], ("true", "false"))

    def test_json(self):
        with open(self.json) as f:
            doc = json.load(f)
        g = next(x for x in doc["groups"] if x["method"] == "pem")
        per = independent("pem")
        self.assertEqual(g["n_participants"], 5)
        self.assertTrue(g["is_default"])
        self.assertAlmostEqual(g["elements"]["K22"]["mean"], statistics.mean(v["K22"] for v in per.values()), places=6)

    def test_different_settings_refused(self):
        with open(FX.GROUP_JSON[0]) as f:
            doc = json.load(f)
        doc["sessions"][0]["settings"]["t_est_s"] = 0.1
        p = os.path.join(self.d, "other.json")
        with open(p, "w") as f:
            json.dump(doc, f)
        r = subprocess.run([sys.executable, "-m", "manipplot.group"] + FX.GROUP_JSON[1:] + [p],
                           capture_output=True, text=True)
        self.assertEqual(r.returncode, 2)
        self.assertIn("t_est_s", r.stderr)
        r = subprocess.run([sys.executable, "-m", "manipplot.group"] + FX.GROUP_JSON[1:] + [p, "--split-by-settings"],
                           capture_output=True, text=True)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertIn("mean (std), n = 4", r.stdout)
        self.assertIn("mean (std), n = 1", r.stdout)


if __name__ == "__main__":
    unittest.main()
