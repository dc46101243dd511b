import csv
import io
import math
import re
import unittest

from manipplot import analysis as A
from manipplot import tables as T
from manipplot.io import parse_results

from .util import results_doc, summary


class FmtNum(unittest.TestCase):
    def test_rounding_and_notation(self):
        self.assertEqual(T.fmt_num(19.785123), "19.79")
        self.assertEqual(T.fmt_num(-12174.489), "-12174")
        self.assertEqual(T.fmt_num(305158526.4), "3.052e+08")
        self.assertEqual(T.fmt_num(-7500000.9), "-7.500e+06")
        self.assertEqual(T.fmt_num(0.000012), "1.200e-05")
        self.assertEqual(T.fmt_num(float("nan")), "n/a")
        self.assertEqual(T.fmt_num(None), "n/a")
        self.assertEqual(T.fmt_num(0.0), "0")
        for x in (1e-9, 3.3, -7.94, 313.75, 123456.7, -9.9e12):
            self.assertLessEqual(abs(float(T.fmt_num(x)) - x), 5e-4 * abs(x), x)


class TextTable(unittest.TestCase):
    def test_columns_never_fuse(self):
        # The case: "oe-trial     30    305158526.4-7500000.9"
        rows = [["oe-trial", "30", T.fmt_num(305158526.4), T.fmt_num(-7500000.9)],
                ["pem", "330", T.fmt_num(1.5), T.fmt_num(-2.25)]]
        txt = T.text_table(["method", "angle [deg]", "K11 [N/m]", "K12 [N/m]"], rows)
        lines = txt.splitlines()
        # Every data line splits into exactly the row's cells, and each number parses back.
        for line, row in zip(lines[2:], rows):
            cells = line.split()
            self.assertEqual(cells, row)
            for c in cells[1:]:
                float(c)
        # Columns line up: each cell ends at the same position as its header.
        hdr_ends = [m.end() for m in re.finditer(r"-+", lines[1])]
        for line in lines[2:]:
            ends = [m.end() for m in re.finditer(r"\S+", line)]
            self.assertEqual(ends[1:], hdr_ends[1:])

    def test_wide_values_widen_the_column(self):
        txt = T.text_table(["a", "b"], [["x", "1" * 40], ["y", "2"]])
        self.assertEqual(len(txt.splitlines()[0]), len("x") + 2 + 40)

    def test_bad_row_refused(self):
        with self.assertRaises(ValueError):
            T.text_table(["a", "b"], [["1"]])


class SessionTable(unittest.TestCase):
    def setUp(self):
        self.r = parse_results(results_doc()).sessions[0]

    def test_elements_labelled_with_units_default_and_biased_marked(self):
        txt = T.session_table_text(self.r)
        header = txt.splitlines()[1]
        for n in ("D11", "D12", "D21", "D22"):
            self.assertIn("%s [N s/m]" % n, header)
        for n in ("K11", "K12", "K21", "K22"):
            self.assertIn("%s [N/m]" % n, header)
        pem = next(l for l in txt.splitlines() if l.startswith("pem "))
        self.assertIn("default, recommended", pem)
        pp = next(l for l in txt.splitlines() if l.startswith("paper-pooled "))
        self.assertIn("BIASED", pp)
        oe = next(l for l in txt.splitlines() if l.startswith("oe "))
        self.assertNotIn("BIASED", oe)
        self.assertNotIn("default", oe)
        self.assertIn("BIASED: paper-pooled", txt)
        # Interval of D11 of pem printed next to its estimate.
        s = self.r.summary("pem")
        self.assertIn("%s [%s, %s]" % (T.fmt_num(s.D[0, 0]), T.fmt_num(s.D_lo[0, 0]), T.fmt_num(s.D_hi[0, 0])), pem)

    def test_truth_errors_labelled(self):
        txt = T.truth_error_text(self.r)
        for n in A.ELEMENT_NAMES:
            self.assertIn("%s err [%%]" % n, txt)
        pp = next(l for l in txt.splitlines() if l.startswith("paper-pooled"))
        self.assertEqual(pp.split()[1:], ["50.0"] * 8)   # 1.5x truth, 3 significant digits

    def test_directional_csv_typed(self):
        rows = T.directional_rows(self.r, "pem")
        buf = io.StringIO()
        T.write_csv(buf, T.DIRECTIONAL_COLUMNS, rows)
        got = list(csv.DictReader(io.StringIO(buf.getvalue())))
        self.assertEqual([float(g["angle_deg"]) for g in got], [30, 60, 120, 150, 210, 240, 300, 330])
        for g in got:
            self.assertTrue(math.isfinite(float(g["uKu_Npm"])))
            self.assertLess(float(g["uKu_ci95_lo_Npm"]), float(g["uKu_Npm"]))
            self.assertEqual(g["identifiable"], "false")
            self.assertTrue(g["flag_reason"])
        for c in T.DIRECTIONAL_COLUMNS:
            if c.startswith("u"):
                self.assertTrue(c.endswith("_Nspm") or c.endswith("_Npm"), c)


if __name__ == "__main__":
    unittest.main()
