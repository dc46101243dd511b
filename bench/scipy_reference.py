#!/usr/bin/env python3
"""SciPy reference for the estimator benchmark (docs/benchmarks.md, "## Estimator").

Reads a manip session log with lcm.EventLog, decodes MANIP_SESSION / MANIP_STATE /
MANIP_TRIAL with the generated Python types, builds per-trial arrays (START=1,
ONSET=2, END=3; ABORT=4 drops the trial) in the shoulder frame, then times ONLY the
whole-array SciPy signal chain of the paper method (§3.1, eq. 21, eq. 30-32) per trial:

  perturbed trials:  savgol_filter(x, 225, 5, deriv=d, delta=1/fs, mode='interp')
                     (d = 1, 2, 3 with --chain full, the brief's chain; d = 3 only with
                     --chain minimal, which is what the C++ needs), both axes;
                     butter(5, 1, 'highpass', fs, output='sos') + sosfiltfilt of the jerk;
                     cumulative_trapezoid from onset over 150 ms -> Δẍ, Δẋ, Δx;
                     eq. 21 Δu_ext; force route (savgol deriv=1 of f_sensor, sosfiltfilt,
                     integrate); numpy lstsq of the 7-parameter model (D 2x2, K symmetric)
                     with M fixed.
  every trial:       welch PSD of the x2 jerk (nperseg = trial length, nfft = 65536).

M is fixed per trial: the C++ uses M_BSP at onset from the arm model (eq. 16); here a
constant 2x2 matrix is used (a 2x2 evaluation per trial, negligible either way).

Prints machine-readable lines:
  RESULT py-decode  median_s=... min_s=... max_s=... reps=...
  RESULT py-proc-<chain> median_s=... min_s=... max_s=... reps=...
  RESULT py-proc-<chain>-cpu ...   (process CPU time of the same runs)
"""
import argparse
import os
import statistics
import sys
import time

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.signal import butter, savgol_filter, sosfiltfilt, welch

HERE = os.path.dirname(os.path.abspath(__file__))


def load(path):
    """Read + decode + per-trial arrays. Returns (info, trials)."""
    import lcm
    from manip import session_t, state_t, trial_event_t

    log = lcm.EventLog(path, "r")
    session = None
    cycles, xs, fs_, us, xrefs = [], [], [], [], []
    events = []
    for ev in log:
        ch = ev.channel
        if ch == "MANIP_STATE":
            s = state_t.decode(ev.data)
            cycles.append(s.cycle)
            xs.append(s.x_workspace_m)
            fs_.append(s.f_sensor_workspace_n)
            us.append(s.u_pert_workspace_n)
            xrefs.append(s.x_ref_workspace_m)
        elif ch == "MANIP_TRIAL":
            events.append(trial_event_t.decode(ev.data))
        elif ch == "MANIP_SESSION":
            session = session_t.decode(ev.data)
    log.close()
    if session is None:
        raise SystemExit(f"{path}: no MANIP_SESSION message")

    cycles = np.asarray(cycles, dtype=np.int64)
    c = np.cos(session.workspace_to_shoulder_rot_rad)
    s = np.sin(session.workspace_to_shoulder_rot_rad)
    rot = np.array([[c, -s], [s, c]])
    origin = np.asarray(session.workspace_origin_in_shoulder_m)
    x = np.asarray(xs) @ rot.T + origin
    xref = np.asarray(xrefs) @ rot.T + origin
    f = np.asarray(fs_) @ rot.T
    u = np.asarray(us) @ rot.T
    c0 = int(cycles[0])
    if not np.all(np.diff(cycles) == 1):
        print("warning: cycle counter has gaps; trial slicing assumes none", file=sys.stderr)

    info = dict(
        fs=session.sample_rate_hz,
        m_dev=np.diag(np.asarray(session.m_adm_kg) + np.asarray(session.m_handle_kg)),
        d_adm=np.diag(np.asarray(session.d_adm_nspm)),
        m_handle=np.diag(np.asarray(session.m_handle_kg)),
        rot=rot,
    )
    trials = []
    cur = None
    for e in events:
        if e.kind == trial_event_t.START:
            cur = dict(trial=e.trial, start=e.cycle, onset=-1, perturbed=bool(e.perturbed),
                       angle=e.pert_angle_rad)
        elif e.kind == trial_event_t.ONSET and cur is not None:
            cur["onset"] = e.cycle - cur["start"]
        elif e.kind == trial_event_t.END and cur is not None:
            a, b = cur["start"] - c0, e.cycle - c0 + 1
            cur.update(x=np.ascontiguousarray(x[a:b]), f=np.ascontiguousarray(f[a:b]),
                       u=np.ascontiguousarray(u[a:b]), xref=np.ascontiguousarray(xref[a:b]))
            if cur["perturbed"] and not (0 <= cur["onset"] < b - a):
                cur["perturbed"] = False
            trials.append(cur)
            cur = None
        else:  # ABORT or stray event
            cur = None
    return info, trials


def process(info, trials, chain="full", window=225, order=5, hp_hz=1.0, t_est=0.150, nfft=65536):
    """The timed part: paper-method signal chain + PSD + per-trial LS. Returns per-trial D, K."""
    fs = info["fs"]
    dt = 1.0 / fs
    sos = butter(5, hp_hz, "highpass", fs=fs, output="sos")
    n_win = int(round(t_est * fs)) + 1
    m_dev, d_adm, m_handle = info["m_dev"], info["d_adm"], info["m_handle"]
    m_fixed = np.array([[2.0, 0.3], [0.3, 1.5]])  # M held fixed in the fit (eq. 32)
    derivs = (1, 2, 3) if chain == "full" else (3,)
    psd_sum = None
    results = []
    for tr in trials:
        xx = tr["x"]
        if len(xx) < window:
            continue
        if not tr["perturbed"]:
            j2 = savgol_filter(xx[:, 1], window, order, deriv=3, delta=dt, mode="interp")
        else:
            on = tr["onset"]
            if on + n_win > len(xx):
                continue
            sg = {d: savgol_filter(xx, window, order, deriv=d, delta=dt, mode="interp", axis=0) for d in derivs}
            jerk = sg[3]
            j2 = jerk[:, 1]
            hp = sosfiltfilt(sos, jerk, axis=0)
            acc = cumulative_trapezoid(hp[on:on + n_win], dx=dt, axis=0, initial=0)
            vel = cumulative_trapezoid(acc, dx=dt, axis=0, initial=0)
            pos = cumulative_trapezoid(vel, dx=dt, axis=0, initial=0)
            u = tr["u"][on:on + n_win]
            du_ext = u - acc @ m_dev.T - vel @ d_adm.T  # eq. 21
            # Force route: Δf_s from the sensor.
            frate = savgol_filter(tr["f"], window, order, deriv=1, delta=dt, mode="interp", axis=0)
            fhp = sosfiltfilt(sos, frate, axis=0)
            dfs = cumulative_trapezoid(fhp[on:on + n_win], dx=dt, axis=0, initial=0)
            du_force = -(dfs + acc @ m_handle.T)
            # eq. 30-32: b = Δu_ext - M Δẍ = D Δẋ + K Δx, K symmetric: [D11 D12 D21 D22 K11 K12 K22]
            b = du_ext - acc @ m_fixed.T
            a = np.zeros((2 * n_win, 7))
            a[:n_win, 0:2] = vel
            a[:n_win, 4:6] = pos
            a[n_win:, 2:4] = vel
            a[n_win:, 5] = pos[:, 0]
            a[n_win:, 6] = pos[:, 1]
            p, *_ = np.linalg.lstsq(a, np.concatenate([b[:, 0], b[:, 1]]), rcond=None)
            results.append((tr["trial"], p, float(du_force[-1, 0])))
        fr, pxx = welch(j2, fs=fs, nperseg=len(j2), nfft=nfft)
        psd_sum = pxx if psd_sum is None else psd_sum + pxx
    return results, psd_sum


def summary(name, v):
    return (f"RESULT {name} median_s={statistics.median(v):.4f} min_s={min(v):.4f} "
            f"max_s={max(v):.4f} reps={len(v)}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("--python-types", default=os.path.join(HERE, "..", "build-bench", "python"),
                    help="directory holding the generated manip/ Python package")
    ap.add_argument("--reps", type=int, default=3, help="repetitions of the processing (median reported)")
    ap.add_argument("--decode-reps", type=int, default=1, help="repetitions of read + decode")
    ap.add_argument("--chain", choices=["full", "minimal", "both"], default="both")
    args = ap.parse_args()
    sys.path.insert(0, os.path.abspath(args.python_types))

    td = []
    for _ in range(max(1, args.decode_reps)):
        t0 = time.perf_counter()
        info, trials = load(args.log)
        td.append(time.perf_counter() - t0)
    n_pert = sum(t["perturbed"] for t in trials)
    print(f"py: {len(trials)} trials, {n_pert} perturbed, "
          f"{sum(len(t['x']) for t in trials)} samples", file=sys.stderr)
    print(summary("py-decode", td))
    chains = ["full", "minimal"] if args.chain == "both" else [args.chain]
    times = {c: [] for c in chains}
    cpu = {c: [] for c in chains}
    for _ in range(args.reps):
        for c in chains:  # interleaved
            c0 = time.process_time()  # all threads (BLAS may use several), like the C++ -cpu lines
            t0 = time.perf_counter()
            res, _psd = process(info, trials, chain=c)
            times[c].append(time.perf_counter() - t0)
            cpu[c].append(time.process_time() - c0)
    print(f"py: {len(res)} per-trial fits", file=sys.stderr)
    for c in chains:
        print(summary(f"py-proc-{c}", times[c]))
    for c in chains:
        print(summary(f"py-proc-{c}-cpu", cpu[c]))


if __name__ == "__main__":
    main()
