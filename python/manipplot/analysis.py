"""Numbers behind the figures and tables (numpy/scipy only, no plotting).

* :func:`jerk_psds` - Fig. 3: Welch PSDs of the principal-axis (x2) jerk, mean
  over unperturbed and over perturbed trials, computed from a log exactly as
  the estimator does (docs/estimator.md, pipeline steps 2 and 4).
* :func:`nrmse_curves` - Fig. 4: NRMSE(dt) of the isolated variational
  signals against the simulator's twin truth (paper §4.3).
* :func:`directional` - per-angle impedance along the push direction
  u = (cos phi, sin phi): u^T K u [N/m] and u^T D u [N s/m], with intervals.
* :func:`group_table` - Table-1 style mean (std) over participants.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence

import numpy as np

from .io import BIASED_METHODS, ELEMENTS, Log, Results, SessionResult, Summary

SIGNALS = ("dx", "dxd", "dxdd", "du_ext")
#: Paper §4.3 / Fig. 4: NRMSE bounds at dt = 150 ms.
PAPER_BOUNDS = {"dx": 0.05, "dxd": 0.05, "dxdd": 0.075, "du_ext": 0.15}


# --------------------------------------------------------------------------- Fig. 3
def sg_window_of(s: SessionResult, fs_hz: float) -> int:
    """The SG window the estimator used (JSON ``sg_window``); without it the default design
    (order 5, -3 dB at 30 Hz: 225 samples at 4 kHz) scaled to fs."""
    for v in (s.raw.get("sg_window"), s.settings.get("sg_window")):
        if isinstance(v, (int, float)) and v > 0:
            return int(v)
    w = int(round(225 * fs_hz / 4000.0))
    return w if w % 2 else w + 1


@dataclass
class Psds:
    f_hz: np.ndarray
    p_unperturbed: np.ndarray     # (m/s^3)^2/Hz, mean over trials
    p_perturbed: np.ndarray
    n_unperturbed: int
    n_perturbed: int
    peak_unperturbed_hz: float
    cutoff_auto_hz: Optional[float]
    threshold_db: float

    def db(self, p: np.ndarray) -> np.ndarray:
        """10 log10(P / P_ref), P_ref = peak of the unperturbed PSD (the dB reference)."""
        return 10.0 * np.log10(np.asarray(p) / self.reference)

    @property
    def reference(self) -> float:
        return float(np.max(self.p_unperturbed[1:])) if self.n_unperturbed else float(np.max(self.p_perturbed[1:]))


def psd_stats(f, pu, pp, nu, npert, threshold_db=3.0) -> Psds:
    f, pu, pp = np.asarray(f, float), np.asarray(pu, float), np.asarray(pp, float)
    ip = int(np.argmax(pu[1:]) + 1) if nu else 0
    cut = None
    if nu and npert:
        with np.errstate(divide="ignore", invalid="ignore"):
            r = 10 * np.log10(pp / pu)
        above = np.nonzero(r[ip:] > threshold_db)[0]
        if above.size:
            cut = float(f[ip + above[0]])
    return Psds(f, pu, pp, nu, npert, float(f[ip]), cut, threshold_db)


def jerk_psds(log: Log, sg_window: int, sg_order: int = 5, nfft: int = 65536, threshold_db: float = 3.0,
              exclude: Sequence[int] = ()) -> Psds:
    from scipy.signal import savgol_filter, welch
    fs = log.sample_rate_hz
    acc = {True: None, False: None}
    n = {True: 0, False: 0}
    f = None
    for t in log.trials:
        if t.aborted or t.index in exclude or len(t) < sg_window:
            continue
        if t.perturbed and t.onset_cycle is None:
            continue
        j = savgol_filter(t.x_m[:, 1], sg_window, sg_order, deriv=3, delta=1.0 / fs, mode="interp")
        nper = min(len(j), nfft)
        f, p = welch(j, fs=fs, window="hann", nperseg=nper, noverlap=nper // 2, nfft=nfft)
        acc[t.perturbed] = p if acc[t.perturbed] is None else acc[t.perturbed] + p
        n[t.perturbed] += 1
    if f is None:
        raise ValueError("no trial long enough for the PSD")
    pu = acc[False] / n[False] if n[False] else np.full_like(f, np.nan)
    pp = acc[True] / n[True] if n[True] else np.full_like(f, np.nan)
    return psd_stats(f, pu, pp, n[False], n[True], threshold_db)


def psds_from_results(s: SessionResult) -> Optional[Psds]:
    """PSD arrays if the JSON carries them (``psd.f_hz``, ``psd.p_unperturbed``, ``psd.p_perturbed``)."""
    p = s.psd or {}
    if all(p.get(k) is not None for k in ("f_hz", "p_unperturbed", "p_perturbed")):
        return psd_stats(p["f_hz"], p["p_unperturbed"], p["p_perturbed"], int(p.get("n_unperturbed", 1)),
                         int(p.get("n_perturbed", 1)), float(s.settings.get("cutoff_auto_threshold_db", 3.0)))
    return None


# --------------------------------------------------------------------------- Fig. 4
@dataclass
class Nrmse:
    dt_s: np.ndarray
    mean: Dict[str, np.ndarray]   # signal -> (n_points, 2) fraction (not %)
    std: Dict[str, np.ndarray]
    n_trials: int
    isolation: str = "paper"


def true_variations(log: Log, trial_index: int, n_win: int) -> Optional[Dict[str, np.ndarray]]:
    """Twin truth of a perturbed trial from onset: dx, dxd, dxdd (reference minus twin reference)
    and du_ext by eq. 21 on the exact signals (as the C++ validation)."""
    t = next((x for x in log.trials if x.index == trial_index), None)
    if t is None or t.twin_x_ref_m is None or t.onset_index is None:
        return None
    on = t.onset_index
    sl = slice(on, on + n_win)
    dx = t.x_ref_m[sl] - t.twin_x_ref_m[sl]
    dxd = t.xd_ref_mps[sl] - t.twin_xd_ref_mps[sl]
    dxdd = t.xdd_ref_mps2[sl] - t.twin_xdd_ref_mps2[sl]
    m_dev = log.m_adm_kg + log.m_handle_kg
    du = t.u_pert_n[sl] - dxdd @ m_dev.T - dxd @ log.d_adm_nspm.T
    return {"dx": dx, "dxd": dxd, "dxdd": dxdd, "du_ext": du}


def nrmse_one(est: np.ndarray, tru: np.ndarray, fs_hz: float, dt_s: np.ndarray, t_norm_s: float) -> np.ndarray:
    """NRMSE(dt) = RMS(est - truth over [0, dt]) / max|truth| over [0, t_norm], per axis."""
    n = min(len(est), len(tru))
    n_norm = min(n, int(round(t_norm_s * fs_hz)) + 1)
    peak = np.max(np.abs(tru[:n_norm]), axis=0)
    out = []
    for dt in dt_s:
        k = min(n, int(round(dt * fs_hz)) + 1)
        out.append(np.sqrt(np.mean((est[:k] - tru[:k]) ** 2, axis=0)) / peak)
    return np.array(out)


def nrmse_curves(log: Log, signals: Dict[int, Dict[str, np.ndarray]], t_norm_s: float = 0.15,
                 n_points: int = 30) -> Nrmse:
    fs = log.sample_rate_hz
    dt_s = t_norm_s * np.arange(1, n_points + 1) / n_points
    per = {s: [] for s in SIGNALS}
    for k, sig in signals.items():
        n = len(sig["t_s"])
        tru = true_variations(log, k, n)
        if tru is None:
            continue
        for s in SIGNALS:
            per[s].append(nrmse_one(sig[s], tru[s], fs, dt_s, t_norm_s))
    nt = len(per["dx"])
    if nt == 0:
        raise ValueError("no exported trial has twin truth in the log (not a simulated log?)")
    mean = {s: np.mean(per[s], axis=0) for s in SIGNALS}
    std = {s: (np.std(per[s], axis=0, ddof=1) if nt > 1 else np.zeros_like(mean[s])) for s in SIGNALS}
    return Nrmse(dt_s, mean, std, nt)


def nrmse_from_validation(doc: dict, key: str = "nrmse") -> Nrmse:
    """Curves from ``manip_sim --validate DIR``'s validation.json."""
    c = doc[key]
    mean, std = {}, {}
    for s in SIGNALS:
        mean[s] = np.column_stack([c[s]["x1"]["mean"], c[s]["x2"]["mean"]])
        std[s] = np.column_stack([c[s]["x1"]["std"], c[s]["x2"]["std"]])
    return Nrmse(np.asarray(c["dt_s"], float), mean, std, int(c.get("n_trials", 0)), str(c.get("isolation", "paper")))


# --------------------------------------------------------------------------- directional impedance
def direction(angle_deg: float) -> np.ndarray:
    a = math.radians(angle_deg)
    return np.array([math.cos(a), math.sin(a)])


def quad(M: np.ndarray, angle_deg) -> np.ndarray:
    """u^T M u for u = (cos phi, sin phi); vectorised over angle_deg."""
    a = np.radians(np.asarray(angle_deg, float))
    c, s = np.cos(a), np.sin(a)
    return M[0, 0] * c * c + (M[0, 1] + M[1, 0]) * c * s + M[1, 1] * s * s


def quad_gradient(angle_deg: float) -> np.ndarray:
    u = direction(angle_deg)
    return np.array([u[0] * u[0], u[0] * u[1], u[1] * u[0], u[1] * u[1]])


def t_quantile_975(dof: int) -> float:
    from scipy.stats import t
    return float(t.ppf(0.975, max(1, dof)))


@dataclass
class Directional:
    angle_deg: float
    which: str                    # "D" [N s/m] or "K" [N/m]
    value: float
    lo: Optional[float]
    hi: Optional[float]
    interval: str                 # how the interval was obtained
    n_trials: Optional[int]
    identifiable: Optional[bool]
    flag: str

    @property
    def unit(self) -> str:
        return "N s/m" if self.which == "D" else "N/m"


def _ci_factor(s: Summary, which: str) -> Optional[float]:
    """The interval half-width / SE the estimator used (t quantile), from its own numbers."""
    M, sp = getattr(s, which), getattr(s, which + "_spread")
    hi = getattr(s, which + "_hi")
    if M is None or sp is None or hi is None:
        return None
    with np.errstate(divide="ignore", invalid="ignore"):
        r = (hi - M) / sp
    r = r[np.isfinite(r) & (sp > 0)]
    return float(np.median(r)) if r.size else None


def directional(s: Summary, which: str, trials: Optional[List[dict]] = None) -> Optional[Directional]:
    """Directional impedance of one per-angle summary.

    Interval, in order of preference:
      1. the estimator's own directional result (``<D|K>_dir`` fields) if the JSON has it;
      2. per-trial methods with per-trial fits in the JSON: mean and t interval over the
         trials' directional values (trials are independent);
      3. the covariance of the fit (``K_cov`` / ``cov_DK``): se = sqrt(g^T C g);
      4. otherwise a conservative bound: se <= sum |g_i| se_i (exact when the elements'
         errors are perfectly correlated; the JSON carries no covariance).
    """
    if s.angle_deg is None:
        return None
    M = getattr(s, which)
    if M is None:
        return None
    phi = s.angle_deg
    r = s.raw
    base = dict(angle_deg=phi, which=which, n_trials=s.n_trials, identifiable=s.identifiable, flag=s.flag)
    unit_key = "Nspm" if which == "D" else "Npm"
    for key in ("%s_dir_%s" % (which, unit_key), "%s_dir" % which):
        if isinstance(r.get(key), (int, float)):
            lo, hi = r.get("%s_dir_ci95_lo" % which), r.get("%s_dir_ci95_hi" % which)
            # The estimator's 1-D fit along the push is what one direction
            # determines: its own flag, not the (unidentifiable) 2x2's.
            if "dir_identifiable" in r:
                base.update(identifiable=bool(r["dir_identifiable"]), flag=str(r.get("dir_flag") or ""),
                            n_trials=r.get("dir_n_trials", s.n_trials))
            label = "t over %d trials (95 %%)" % r["dir_n_trials"] if r.get("dir_n_trials") else "estimator (95 %)"
            return Directional(value=float(r[key]), lo=lo, hi=hi, interval=label, **base)
    g = quad_gradient(phi)
    value = float(quad(M, phi))
    if trials:
        vals = []
        for t in trials:
            if t.get("method") != s.method:
                continue
            a = t.get("angle_deg")
            if not isinstance(a, (int, float)) or not math.isfinite(a) or abs(((a - phi + 180) % 360) - 180) > 1e-6:
                continue
            key = "D_Nspm" if which == "D" else "K_Npm"
            if t.get(key) is None:
                continue
            Mt = np.asarray(t[key], float).reshape(2, 2)
            vals.append(float(quad(Mt, phi)))
        if len(vals) >= 2:
            v = np.asarray(vals)
            m, sd = float(v.mean()), float(v.std(ddof=1))
            h = t_quantile_975(len(v) - 1) * sd / math.sqrt(len(v))
            return Directional(value=m, lo=m - h, hi=m + h, interval="t over %d trials (95 %%)" % len(v), **base)
    C = s.cov(which)
    f = _ci_factor(s, which) or 1.959963984540054
    if C is not None:
        se = math.sqrt(max(0.0, float(g @ C @ g)))
        return Directional(value=value, lo=value - f * se, hi=value + f * se, interval="covariance (95 %)", **base)
    sp = getattr(s, which + "_spread")
    if sp is not None and np.all(np.isfinite(sp.ravel())):
        se = float(np.abs(g) @ np.abs(sp.ravel()))
        return Directional(value=value, lo=value - f * se, hi=value + f * se,
                           interval="conservative bound (no covariance in JSON)", **base)
    return Directional(value=value, lo=None, hi=None, interval="none", **base)


def directional_table(s: SessionResult, method: str) -> List[Directional]:
    out = []
    for summ in s.per_angle(method):
        for which in ("D", "K"):
            d = directional(summ, which, s.trials)
            if d is not None:
                out.append(d)
    return out


# --------------------------------------------------------------------------- groups
class GroupError(ValueError):
    pass


#: Settings that may differ between sessions of one group (file names, logs).
SETTINGS_IGNORED = {"log", "json", "csv", "plots", "export_signals", "report", "quiet", "config"}


def settings_difference(a: dict, b: dict) -> List[str]:
    keys = sorted((set(a) | set(b)) - SETTINGS_IGNORED)
    return [k for k in keys if a.get(k) != b.get(k)]


@dataclass
class GroupRow:
    participant: str
    log: str
    summary: Summary


@dataclass
class GroupTable:
    method: str
    rows: List[GroupRow]
    mean: Dict[str, float] = field(default_factory=dict)   # "D11" -> mean over participants
    std: Dict[str, float] = field(default_factory=dict)    # sample std (ddof = 1), as the paper's Table 1

    @property
    def n(self) -> int:
        return len(self.rows)

    @property
    def biased(self) -> Optional[str]:
        return BIASED_METHODS.get(self.method)


def element_value(s: Summary, name: str, part: str = "est") -> float:
    """name 'D11'..'K22'; part 'est' | 'lo' | 'hi' | 'spread'."""
    which, e = name[0], name[1:]
    i = ELEMENTS.index(e)
    M = {"est": getattr(s, which), "lo": getattr(s, which + "_lo"), "hi": getattr(s, which + "_hi"),
         "spread": getattr(s, which + "_spread")}[part]
    return float("nan") if M is None else float(M.ravel()[i])


ELEMENT_NAMES = tuple("D" + e for e in ELEMENTS) + tuple("K" + e for e in ELEMENTS)


def collect_sessions(results: Sequence[Results]) -> List[SessionResult]:
    return [s for r in results for s in r.sessions]


def check_same_configuration(sessions: Sequence[SessionResult]) -> None:
    """Refuse to pool sessions estimated with different settings (named)."""
    if not sessions:
        raise GroupError("no sessions")
    ref = sessions[0]
    for s in sessions[1:]:
        diff = settings_difference(ref.settings, s.settings)
        if diff:
            raise GroupError("%s and %s were estimated with different settings (%s); group them separately "
                             "(--split-by-settings) or re-estimate with one configuration"
                             % (ref.log, s.log, ", ".join("%s: %r vs %r" % (k, ref.settings.get(k), s.settings.get(k))
                                                           for k in diff[:4])))


def split_by_settings(sessions: Sequence[SessionResult]) -> List[List[SessionResult]]:
    groups: List[List[SessionResult]] = []
    for s in sessions:
        for g in groups:
            if not settings_difference(g[0].settings, s.settings):
                g.append(s)
                break
        else:
            groups.append([s])
    return groups


def group_table(sessions: Sequence[SessionResult], method: str) -> GroupTable:
    rows = []
    labels = [s.participant for s in sessions]
    for s, lab in zip(sessions, labels):
        summ = s.summary(method, "session")
        if summ is None or summ.D is None or summ.K is None:
            raise GroupError("%s has no session estimate for method %s" % (s.log, method))
        if labels.count(lab) > 1:   # e.g. every manip_sim log says "sim": tell them apart by the log's name
            lab = "%s (%s)" % (lab, os.path.splitext(os.path.basename(s.log))[0])
        rows.append(GroupRow(lab, s.log, summ))
    g = GroupTable(method, rows)
    for name in ELEMENT_NAMES:
        v = np.array([element_value(r.summary, name) for r in rows])
        g.mean[name] = float(np.mean(v))
        g.std[name] = float(np.std(v, ddof=1)) if len(v) > 1 else float("nan")
    return g
