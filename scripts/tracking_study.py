#!/usr/bin/python3
"""The tracking study (docs/diagnosis.md, "Tracking study"): manip_rt sessions
whose simulated stages track the admittance reference through a PD of lower
bandwidth, diagnosed from the log alone.

Each cell is a PD bandwidth (Hz); the shipped rt.yaml has 25 Hz
(kp = m w^2, kd = 2 zeta m w), so a cell scales kp by (f/25)^2 and kd by
f/25. Each session: a seeded rt.yaml variant (protocol seed and the
participant's seed both = the session seed), `manip_rt --backend sim`, then
`diagnose_model --json` and `estimate_impedance --position-source S --json`
for each S of --sources (default the encoder: the paper's position, for
comparison; the default "auto" is the reference on these logs);
--no-diagnosis runs the estimator alone. diagnose_model sees only the log.

Per session: whether the tracking was named (the diagnosis moved to the
reference), its share, coefficient (1 when the routes differ by the
tracking alone) and held-out share, what else was named, and the corrected
D, K against the simulated person's (linear, so intrinsic = apparent):
Frobenius and the diagonal elements, the issue's D within 20 %, K within
10 %. Prints one Markdown row per cell and, with --verbose, one line per
session.

    scripts/tracking_study.py --build build --cells 25,15,10 --seeds 20 [--noise realistic] [--jobs 2] [--keep DIR]
        [--sources encoder,reference,tracked] [--no-diagnosis] [--verbose]

Prints a table of the estimator per position source, then (without
--no-diagnosis) the diagnosis' table.
"""
import argparse
import concurrent.futures as cf
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile

import numpy as np

SRC = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NOMINAL_HZ = 25.0


def set_key(text, key, value):
    """Replaces the value of one `key:` line of rt.yaml, keeping its comment."""
    pat = re.compile(r"^(\s*" + re.escape(key) + r":\s*)([^#\n]*?)(\s*#.*)?$", re.M)
    if not pat.search(text):
        raise KeyError(key)
    return pat.sub(lambda m: m.group(1) + value + (m.group(3) or ""), text, count=1)


def vec(text, key):
    m = re.search(r"^\s*" + re.escape(key) + r":\s*\[([^\]]*)\]", text, re.M)
    return [float(v) for v in m.group(1).split(",")]


def mat(text, key):
    m = re.search(r"^\s*" + re.escape(key) + r":\s*\[\[([^\]]*)\],\s*\[([^\]]*)\]\]", text, re.M)
    return np.array([[float(v) for v in m.group(1).split(",")], [float(v) for v in m.group(2).split(",")]])


def variant(base, bandwidth_hz, seed, noise):
    s = bandwidth_hz / NOMINAL_HZ
    kp = [v * s * s for v in vec(base, "kp_npm")]
    kd = [v * s for v in vec(base, "kd_nspm")]
    t = set_key(base, "kp_npm", "[%g, %g]" % tuple(kp))
    t = set_key(t, "kd_nspm", "[%g, %g]" % tuple(kd))
    t = re.sub(r"^(\s*seed:\s*)1(\s*#\s*participant behaviour)", lambda m: m.group(1) + str(seed) + m.group(2), t, count=1, flags=re.M)
    if noise == "realistic":  # as manip_sim --noise realistic
        t = set_key(t, "force_noise_n", "0.05")
        t = set_key(t, "motor_noise_n", "0.2")
        t = set_key(t, "lateral_bow_std_m", "0.005")
    return t


def run_one(build, base, cell, seed, noise, work, sources, diagnose, keep):
    d = os.path.join(work, "f%g_s%d" % (cell, seed))
    os.makedirs(d, exist_ok=True)
    cfg = os.path.join(d, "rt.yaml")
    with open(cfg, "w") as f:
        f.write(variant(base, cell, seed, noise))
    log = os.path.join(d, "session.lcm")
    rt = subprocess.run([os.path.join(build, "apps/manip_rt"), "--backend", "sim", "--config", cfg, "--seed", str(seed),
                         "--out", log, "--lcm-url", "none", "-q", "--force"], capture_output=True, text=True)
    if rt.returncode != 0:
        return {"cell": cell, "seed": seed, "error": "manip_rt exit %d: %s" % (rt.returncode, rt.stderr.strip()[-300:])}
    out = {"cell": cell, "seed": seed, "src": {}}
    try:
        for src in sources:
            ej = os.path.join(d, src + ".json")
            subprocess.run([os.path.join(build, "apps/estimate_impedance"), log, "--position-source", src, "--json", ej,
                            "--force", "-q"], capture_output=True, text=True)
            if os.path.exists(ej):
                with open(ej) as f:
                    est = json.load(f)
                sm = next(iter(est["sessions"][0]["session_summary"].values()))
                out["src"][src] = (np.array(sm["D_Nspm"]).reshape(2, 2), np.array(sm["K_Npm"]).reshape(2, 2))
        if "encoder" in out["src"]:
            out["d_enc"], out["k_enc"] = out["src"]["encoder"]
        if not diagnose:
            return out
        dj = os.path.join(d, "diagnosis.json")
        dg = subprocess.run([os.path.join(build, "apps/diagnose_model"), log, "--json", dj, "--force", "-q"],
                            capture_output=True, text=True)
        if not os.path.exists(dj):
            return {"cell": cell, "seed": seed, "error": "diagnose_model exit %d: %s" % (dg.returncode, dg.stderr.strip()[-300:])}
        with open(dj) as f:
            dia = json.load(f)
    finally:
        if not keep:  # a manip_rt session log is ~0.4 GB
            os.remove(log)
    tr = dia["manipulandum"]["sensor_disagreement"]["tracking"]
    con = dia["conclusion"]
    out["switched"] = bool(tr.get("switched"))
    for k in ("share", "coef", "heldout_share", "rms_um", "heldout_better_trials", "trials"):
        out[k] = tr.get(k)
    out["named"] = con.get("named", [])
    if "corrected" in con:
        out["d"] = np.array(con["corrected"]["d_nspm"])
        out["k"] = np.array(con["corrected"]["k_npm"])
    return out


def finish(results, work, keep):
    """Lists the failed sessions, removes the temporary directory; the exit status."""
    for r in results:
        if "error" in r:
            print("failed: PD %g Hz seed %d: %s" % (r["cell"], r["seed"], r["error"]))
    if not keep:
        shutil.rmtree(work, ignore_errors=True)
    return 1 if any("error" in r for r in results) else 0


def frob(e, t):
    return float(np.linalg.norm(e - t) / np.linalg.norm(t))


def diag_ok(e, t, tol):
    return all(abs(e[i, i] - t[i, i]) <= tol * abs(t[i, i]) for i in range(2))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", default=os.path.join(SRC, "build"))
    ap.add_argument("--config", default=os.path.join(SRC, "config/rt.yaml"))
    ap.add_argument("--cells", default="25,15,10", help="PD bandwidths in Hz (rt.yaml: 25)")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first-seed", type=int, default=1)
    ap.add_argument("--noise", choices=["none", "realistic"], default="realistic")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--keep", help="keep the sessions and reports in this directory (default: a temporary one, removed)")
    ap.add_argument("--sources", default="encoder",
                    help="estimate_impedance --position-source values run on each session (comma-separated; "
                         "encoder, reference, tracked, auto)")
    ap.add_argument("--no-diagnosis", action="store_true", help="only the estimator (--sources), no diagnose_model")
    ap.add_argument("--verbose", action="store_true")
    a = ap.parse_args()
    with open(a.config) as f:
        base = f.read()
    d_true, k_true = mat(base, "d_nspm"), mat(base, "k_npm")
    cells = [float(c) for c in a.cells.split(",")]
    work = a.keep or tempfile.mkdtemp(prefix="tracking_study_")
    os.makedirs(work, exist_ok=True)
    jobs = [(c, s) for c in cells for s in range(a.first_seed, a.first_seed + a.seeds)]
    results = []
    with cf.ThreadPoolExecutor(max_workers=a.jobs) as ex:
        sources = [x for x in a.sources.split(",") if x]
        futs = {ex.submit(run_one, a.build, base, c, s, a.noise, work, sources, not a.no_diagnosis, bool(a.keep)): (c, s)
                for c, s in jobs}
        for fu in cf.as_completed(futs):
            r = fu.result()
            results.append(r)
            if a.verbose:
                if "error" in r:
                    print("f %g seed %d: %s" % (r["cell"], r["seed"], r["error"]), file=sys.stderr)
                else:
                    est = "".join(" %s D %.1f %% K %.1f %%" % (src, 100 * frob(dk[0], d_true), 100 * frob(dk[1], k_true))
                                  for src, dk in r["src"].items())
                    if "switched" not in r:
                        print("f %g seed %d:%s" % (r["cell"], r["seed"], est), file=sys.stderr, flush=True)
                    else:
                        extra = (" D %.1f %% K %.1f %%" % (100 * frob(r["d"], d_true), 100 * frob(r["k"], k_true))) if "d" in r else ""
                        print("f %g seed %d: moved %s share %.3f coef %.3f held-out %.3f (%s/%s) %.1f um named %s%s;%s" % (
                            r["cell"], r["seed"], r["switched"], r["share"] or 0, r["coef"] or 0, r["heldout_share"] or 0,
                            r.get("heldout_better_trials"), r.get("trials"), r["rms_um"] or 0, r["named"], extra, est),
                            file=sys.stderr, flush=True)
    med = lambda xs: statistics.median(xs) if xs else float("nan")
    # The estimator alone, per position source.
    print("| PD bandwidth | position source | sessions | D within 20 % (Frobenius; D11, D22) | K within 10 % (Frobenius; K11, K22) "
          "| median D, K error |")
    print("|---|---|---|---|---|---|")
    for c in cells:
        for src in sources:
            es = [r["src"][src] for r in results if r["cell"] == c and "error" not in r and src in r["src"]]
            print("| %g Hz | %s | %d | %d/%d; %d/%d | %d/%d; %d/%d | %.1f %%, %.1f %% |" % (
                c, src, len(es), sum(frob(d, d_true) <= 0.2 for d, _ in es), len(es),
                sum(diag_ok(d, d_true, 0.2) for d, _ in es), len(es), sum(frob(k, k_true) <= 0.1 for _, k in es), len(es),
                sum(diag_ok(k, k_true, 0.1) for _, k in es), len(es),
                100 * med([frob(d, d_true) for d, _ in es]), 100 * med([frob(k, k_true) for _, k in es])))
    if a.no_diagnosis:
        return finish(results, work, a.keep)
    print()
    print("| PD bandwidth | sessions | tracking named | coefficient within 0.2 of 1 (median) | held-out share > 0 (median) "
          "| RMS x_ref − x, median | also named | D within 20 % (Frobenius; D11, D22) | K within 10 % (Frobenius; K11, K22) "
          "| median D, K error | encoder: D within 20 %, K within 10 % (Frobenius); median D, K error |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for c in cells:
        rs = [r for r in results if r["cell"] == c and "error" not in r]
        errs = [r for r in results if r["cell"] == c and "error" in r]
        n = len(rs)
        named = sum(r["switched"] for r in rs)
        coef_ok = sum(r["switched"] and abs(r["coef"] - 1) <= 0.2 for r in rs)
        held = sum(r["switched"] and r["heldout_share"] > 0 for r in rs)
        others = {}
        for r in rs:
            for m in r["named"]:
                others[m] = others.get(m, 0) + 1
        wd = [r for r in rs if "d" in r]
        d_ok = sum(frob(r["d"], d_true) <= 0.2 for r in wd)
        d_dg = sum(diag_ok(r["d"], d_true, 0.2) for r in wd)
        k_ok = sum(frob(r["k"], k_true) <= 0.1 for r in wd)
        k_dg = sum(diag_ok(r["k"], k_true, 0.1) for r in wd)
        we = [r for r in rs if "d_enc" in r]
        print("| %g Hz | %d%s | %d/%d | %d/%d (%.3f) | %d/%d (%.3f) | %.1f µm | %s | %d/%d; %d/%d | %d/%d; %d/%d | %.1f %%, %.1f %% | %d/%d, %d/%d; %.1f %%, %.1f %% |" % (
            c, n, (" (%d failed)" % len(errs)) if errs else "", named, n, coef_ok, n, med([r["coef"] for r in rs if r["coef"]]),
            held, n, med([r["heldout_share"] for r in rs if r["heldout_share"] is not None]),
            med([r["rms_um"] for r in rs if r["rms_um"]]),
            ", ".join("%s %d" % kv for kv in sorted(others.items())) or "none",
            d_ok, len(wd), d_dg, len(wd), k_ok, len(wd), k_dg, len(wd),
            100 * med([frob(r["d"], d_true) for r in wd]), 100 * med([frob(r["k"], k_true) for r in wd]),
            sum(frob(r["d_enc"], d_true) <= 0.2 for r in we), len(we), sum(frob(r["k_enc"], k_true) <= 0.1 for r in we), len(we),
            100 * med([frob(r["d_enc"], d_true) for r in we]), 100 * med([frob(r["k_enc"], k_true) for r in we])))
    return finish(results, work, a.keep)


if __name__ == "__main__":
    sys.exit(main())
