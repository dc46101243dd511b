"""Shared helpers for the manipplot tests: synthetic results documents."""
import copy
import json
import os
import tempfile

import numpy as np

D_T1 = [10.98, -7.94, -8.54, 6.75]
K_T1 = [110.52, -106.05, -106.04, 313.75]
ANGLES = (30, 60, 120, 150, 210, 240, 300, 330)


def summary(method, group, D, K, rel_se=0.05, ident=True, n=24, angle=None, kind="pooled", t=2.0):
    D, K = np.asarray(D, float), np.asarray(K, float)
    dse, kse = np.abs(D) * rel_se + 0.1, np.abs(K) * rel_se + 1.0
    d = dict(method=method, group=group, kind=kind, n_trials=n, D_Nspm=D.tolist(), K_Npm=K.tolist(),
             D_spread=dse.tolist(), K_spread=kse.tolist(), D_ci95_lo=(D - t * dse).tolist(),
             D_ci95_hi=(D + t * dse).tolist(), K_ci95_lo=(K - t * kse).tolist(), K_ci95_hi=(K + t * kse).tolist(),
             M_kg=[2.0, -0.5, -0.5, 1.5], identifiable=ident, flag="" if ident else "SE of K22 > 50 %",
             n_flagged_trials=0)
    if angle is not None:
        d["angle_deg"] = angle
    return d


def results_doc(participant="P1", D=D_T1, K=K_T1, methods=("pem", "oe", "paper-pooled"), per_angle=True,
                settings=None, truth=True, log="/nonexistent/p.lcm"):
    sums = []
    for m in methods:
        scale = 1.0 if m != "paper-pooled" else 1.5
        sums.append(summary(m, "session", np.asarray(D) * scale, np.asarray(K) * scale))
    if per_angle:
        for a in ANGLES:
            Ka = list(K)
            Ka[3] = 10067.0
            sums.append(summary(methods[0], "angle %d" % a, D, Ka, rel_se=0.4, ident=False, n=3))
    st = {"t_est_s": 0.15, "methods": list(methods), "sg_order": 5}
    st.update(settings or {})
    return {"manip_version": "0.1.0", "settings": st, "sessions": [{
        "log": log, "session": {"participant_id": participant, "session_id": "s1", "source": "synthetic",
                                "sample_rate_hz": 4000.0},
        "settings": st, "cutoff_used_hz": 1.0, "sg_window": 225,
        "counts": {"trials": 40, "perturbed": 10, "used": 9}, "summaries": sums, "trials": [],
        "psd": {"peak_unperturbed_hz": 0.61}, "truth": {"model": "linear-impedance", "n_trials": 9, "D_Nspm": list(D),
                                                        "K_Npm": list(K), "M_kg": [2, -0.5, -0.5, 1.5]} if truth else None,
        "issues": [{"trial": 7, "reason": "gap in the cycle counter (100 -> 102)"}],
        "warnings": ["example warning"]}]}


def write_json(doc, d=None, name="r.json"):
    d = d or tempfile.mkdtemp(prefix="manipplot_")
    p = os.path.join(d, name)
    with open(p, "w") as f:
        json.dump(doc, f)
    return p
