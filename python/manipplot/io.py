"""Loading manip data into numpy arrays.

* :func:`load_log` reads an LCM event log with ``lcm.EventLog`` and the
  LCM-generated ``manip`` Python types (``build/python/manip`` after a build):
  the session message, the state stream cut into trials (shoulder frame), the
  trial events, and the simulator's truth channels when present.
* :func:`load_results` reads ``estimate_impedance --json`` output
  defensively, by field name: unknown fields are kept in ``raw``, missing
  optional fields become ``None``.
* :func:`load_signals` reads ``estimate_impedance --export-signals DIR``
  (``trial_<k>.csv``).
"""
from __future__ import annotations

import csv
import glob
import json
import math
import os
import re
import sys
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

import numpy as np

#: The estimator's default (recommended) method (docs/estimator.md).
DEFAULT_METHOD = "pem"
#: Methods known to be biased, with the reason shown next to them.
BIASED_METHODS = {
    "paper-pooled": "biased (-68 % to +107 % off in the accuracy study; its narrow 95 % "
                    "intervals cover the truth in 0-5 % of sessions)",
}
ELEMENTS = ("11", "12", "21", "22")

CH_SESSION = "MANIP_SESSION"
CH_STATE = "MANIP_STATE"
CH_TRIAL = "MANIP_TRIAL"
CH_TRUTH_STATE = "MANIP_TRUTH_STATE"
CH_TRUTH_IMPEDANCE = "MANIP_TRUTH_IMPEDANCE"


# --------------------------------------------------------------------------- logs
def _find_types_dir() -> Optional[str]:
    env = os.environ.get("MANIP_LCMTYPES_PYTHON")
    if env:
        return env
    here = os.path.dirname(os.path.abspath(__file__))
    for up in (os.path.join(here, "..", ".."), os.getcwd()):
        cand = os.path.normpath(os.path.join(up, "build", "python"))
        if os.path.isdir(os.path.join(cand, "manip")):
            return cand
    return None


def import_types(types_dir: Optional[str] = None):
    """Import the LCM-generated ``manip`` package (session_t, state_t, ...).

    ``types_dir`` (or ``$MANIP_LCMTYPES_PYTHON``, or ``build/python`` of the
    source tree) is the directory that contains ``manip/``."""
    d = types_dir or _find_types_dir()
    if d and d not in sys.path:
        sys.path.insert(0, d)
    try:
        import manip  # noqa: F401  (the generated package)
        from manip import session_t, state_t, trial_event_t, impedance_truth_t
    except ImportError as e:  # pragma: no cover - message path
        raise ImportError("LCM-generated Python types not found (build the target manip_lcmtypes_gen, "
                          "or set MANIP_LCMTYPES_PYTHON to the directory holding manip/): %s" % e)
    return session_t, state_t, trial_event_t, impedance_truth_t


@dataclass
class Trial:
    """One trial of a log, START..END (inclusive), vectors in the shoulder frame [SI]."""
    index: int
    perturbed: bool
    angle_deg: float                  # perturbation angle (nan if unperturbed)
    start_cycle: int
    end_cycle: Optional[int]
    onset_cycle: Optional[int]
    aborted: bool = False
    reason: str = ""
    cycle: np.ndarray = None          # (n,)
    x_m: np.ndarray = None            # (n, 2) measured handle position
    xd_mps: np.ndarray = None         # (n, 2)
    x_ref_m: np.ndarray = None        # (n, 2) admittance reference
    xd_ref_mps: np.ndarray = None
    xdd_ref_mps2: np.ndarray = None
    f_sensor_n: np.ndarray = None
    u_pert_n: np.ndarray = None
    twin_x_ref_m: Optional[np.ndarray] = None     # unperturbed twin (simulated logs)
    twin_xd_ref_mps: Optional[np.ndarray] = None
    twin_xdd_ref_mps2: Optional[np.ndarray] = None
    truth: Optional[dict] = None                  # impedance_truth_t as dict

    @property
    def onset_index(self) -> Optional[int]:
        return None if self.onset_cycle is None else int(self.onset_cycle - self.start_cycle)

    def __len__(self):
        return 0 if self.cycle is None else len(self.cycle)


@dataclass
class Log:
    path: str
    session: dict
    sample_rate_hz: float
    rotation: np.ndarray              # workspace -> shoulder rotation
    origin_m: np.ndarray              # workspace origin in the shoulder frame
    m_adm_kg: np.ndarray              # 2x2, shoulder frame
    d_adm_nspm: np.ndarray
    m_handle_kg: np.ndarray
    trials: List[Trial] = field(default_factory=list)
    n_states: int = 0

    @property
    def has_truth(self) -> bool:
        return any(t.twin_x_ref_m is not None for t in self.trials)


def _msg_dict(msg) -> dict:
    out = {}
    for name in getattr(msg, "__slots__", []):
        v = getattr(msg, name)
        out[name] = list(v) if isinstance(v, (list, tuple)) else v
    return out


def load_log(path: str, types_dir: Optional[str] = None) -> Log:
    """Read a manip LCM log into numpy arrays (shoulder frame, SI units)."""
    import lcm  # PyPI lcm==1.5.3 in .venv
    session_t, state_t, trial_event_t, impedance_truth_t = import_types(types_dir)
    if not os.path.isfile(path):
        raise FileNotFoundError(path)
    session = None
    cols = {k: [] for k in ("cycle", "trial", "x", "xd", "xr", "xdr", "xddr", "fs", "up")}
    twin = {k: [] for k in ("cycle", "xr", "xdr", "xddr")}
    events: List[Any] = []
    truths: Dict[int, dict] = {}
    log = lcm.EventLog(path, "r")
    for ev in log:
        ch = ev.channel
        if ch == CH_STATE or ch == CH_TRUTH_STATE:
            s = state_t.decode(ev.data)
            if ch == CH_STATE:
                cols["cycle"].append(s.cycle)
                cols["trial"].append(s.trial)
                cols["x"].append(s.x_workspace_m)
                cols["xd"].append(s.xd_workspace_mps)
                cols["xr"].append(s.x_ref_workspace_m)
                cols["xdr"].append(s.xd_ref_workspace_mps)
                cols["xddr"].append(s.xdd_ref_workspace_mps2)
                cols["fs"].append(s.f_sensor_workspace_n)
                cols["up"].append(s.u_pert_workspace_n)
            else:
                twin["cycle"].append(s.cycle)
                twin["xr"].append(s.x_ref_workspace_m)
                twin["xdr"].append(s.xd_ref_workspace_mps)
                twin["xddr"].append(s.xdd_ref_workspace_mps2)
        elif ch == CH_TRIAL:
            events.append(trial_event_t.decode(ev.data))
        elif ch == CH_SESSION and session is None:
            session = _msg_dict(session_t.decode(ev.data))
        elif ch == CH_TRUTH_IMPEDANCE:
            m = impedance_truth_t.decode(ev.data)
            truths[m.trial] = _msg_dict(m)
    log.close()
    if session is None:
        raise ValueError("%s: no %s message (not a manip log?)" % (path, CH_SESSION))
    rot = float(session["workspace_to_shoulder_rot_rad"])
    R = np.array([[math.cos(rot), -math.sin(rot)], [math.sin(rot), math.cos(rot)]])
    o = np.asarray(session["workspace_origin_in_shoulder_m"], float)

    def diag(v):
        return R @ np.diag(np.asarray(v, float)) @ R.T

    L = Log(path=path, session=session, sample_rate_hz=float(session["sample_rate_hz"]), rotation=R,
            origin_m=o, m_adm_kg=diag(session["m_adm_kg"]), d_adm_nspm=diag(session["d_adm_nspm"]),
            m_handle_kg=diag(session["m_handle_kg"]), n_states=len(cols["cycle"]))
    cyc = np.asarray(cols["cycle"], np.int64)
    arr = {k: np.asarray(v, float).reshape(-1, 2) for k, v in cols.items() if k not in ("cycle", "trial")}
    tcyc = np.asarray(twin["cycle"], np.int64)
    tarr = {k: np.asarray(v, float).reshape(-1, 2) for k, v in twin.items() if k != "cycle"}

    def rows(c0, c1, c):
        i0, i1 = np.searchsorted(c, c0), np.searchsorted(c, c1, side="right")
        return slice(int(i0), int(i1))

    by_trial: Dict[int, Trial] = {}
    order: List[int] = []
    for e in events:
        k = int(e.trial)
        if e.kind == trial_event_t.START:
            ang = math.degrees(e.pert_angle_rad) % 360.0 if e.perturbed else float("nan")
            by_trial[k] = Trial(index=k, perturbed=bool(e.perturbed), angle_deg=ang, start_cycle=int(e.cycle),
                                end_cycle=None, onset_cycle=None)
            order.append(k)
        elif k in by_trial:
            t = by_trial[k]
            if e.kind == trial_event_t.ONSET:
                t.onset_cycle = int(e.cycle)
            elif e.kind == trial_event_t.END:
                t.end_cycle = int(e.cycle)
            elif e.kind == trial_event_t.ABORT:
                t.end_cycle = int(e.cycle)
                t.aborted = True
                t.reason = e.reason
    for k in order:
        t = by_trial[k]
        if t.end_cycle is None:
            t.aborted, t.reason = True, t.reason or "no END event"
            continue
        sl = rows(t.start_cycle, t.end_cycle, cyc)
        t.cycle = cyc[sl]
        t.x_m = arr["x"][sl] @ R.T + o
        t.xd_mps = arr["xd"][sl] @ R.T
        t.x_ref_m = arr["xr"][sl] @ R.T + o
        t.xd_ref_mps = arr["xdr"][sl] @ R.T
        t.xdd_ref_mps2 = arr["xddr"][sl] @ R.T
        t.f_sensor_n = arr["fs"][sl] @ R.T
        t.u_pert_n = arr["up"][sl] @ R.T
        if len(tcyc):
            ts = rows(t.start_cycle, t.end_cycle, tcyc)
            if ts.stop - ts.start == len(t.cycle) and np.array_equal(tcyc[ts], t.cycle):
                t.twin_x_ref_m = tarr["xr"][ts] @ R.T + o
                t.twin_xd_ref_mps = tarr["xdr"][ts] @ R.T
                t.twin_xdd_ref_mps2 = tarr["xddr"][ts] @ R.T
        t.truth = truths.get(k)
        L.trials.append(t)
    return L


# --------------------------------------------------------------------------- results JSON
def _mat(v) -> Optional[np.ndarray]:
    """[a11, a12, a21, a22] (nulls allowed) -> 2x2 float array, or None."""
    if v is None:
        return None
    a = np.array([np.nan if x is None else float(x) for x in v], float)
    if a.size != 4:
        return None
    return a.reshape(2, 2)


def _angle_of(d: dict) -> Optional[float]:
    a = d.get("angle_deg")
    if isinstance(a, (int, float)) and math.isfinite(a):
        return float(a)
    m = re.match(r"\s*angle\s+([-+0-9.eE]+)", str(d.get("group", "")))
    return float(m.group(1)) if m else None


@dataclass
class Summary:
    method: str
    group: str                    # "session" or "angle <deg>"
    angle_deg: Optional[float]
    kind: str
    n_trials: Optional[int]
    D: Optional[np.ndarray]       # 2x2 [N s/m]
    K: Optional[np.ndarray]       # 2x2 [N/m]
    D_spread: Optional[np.ndarray]
    K_spread: Optional[np.ndarray]
    D_lo: Optional[np.ndarray]
    D_hi: Optional[np.ndarray]
    K_lo: Optional[np.ndarray]
    K_hi: Optional[np.ndarray]
    identifiable: Optional[bool]
    flag: str
    raw: dict

    @property
    def is_session(self) -> bool:
        return self.group == "session"

    def cov(self, which: str) -> Optional[np.ndarray]:
        """4x4 covariance of vec(D) or vec(K) (row-major), if the JSON carries one.

        Accepted layouts: ``D_cov``/``K_cov`` (16 numbers or 4x4), or ``cov_DK``/``cov``
        (8x8 over [D11..D22, K11..K22])."""
        r = self.raw
        for key in ("%s_cov" % which, "%s_cov_Nspm2" % which, "%s_cov_Npm2" % which):
            if r.get(key) is not None:
                c = np.asarray(r[key], float).reshape(4, 4)
                return c
        for key in ("cov_DK", "cov"):
            if r.get(key) is not None:
                c = np.asarray(r[key], float).reshape(8, 8)
                return c[:4, :4] if which == "D" else c[4:, 4:]
        return None


@dataclass
class SessionResult:
    log: str
    session: dict
    settings: dict
    cutoff_used_hz: Optional[float]
    counts: dict
    summaries: List[Summary]
    trials: List[dict]
    psd: dict
    truth: Optional[dict]
    issues: List[dict]
    warnings: List[str]
    raw: dict

    def summary(self, method: str, group: str = "session") -> Optional[Summary]:
        for s in self.summaries:
            if s.method == method and s.group == group:
                return s
        return None

    def methods(self) -> List[str]:
        seen: List[str] = []
        for s in self.summaries:
            if s.method not in seen:
                seen.append(s.method)
        return seen

    def per_angle(self, method: str) -> List[Summary]:
        out = [s for s in self.summaries if s.method == method and s.angle_deg is not None]
        return sorted(out, key=lambda s: s.angle_deg)

    @property
    def participant(self) -> str:
        p = (self.session or {}).get("participant_id") or ""
        return p or os.path.splitext(os.path.basename(self.log))[0]

    def truth_mats(self):
        if not self.truth:
            return None, None
        return _mat(self.truth.get("D_Nspm")), _mat(self.truth.get("K_Npm"))


@dataclass
class Results:
    path: str
    version: str
    settings: dict
    sessions: List[SessionResult]
    default_method: str
    raw: dict


def _summary(d: dict) -> Summary:
    def b(v):
        return None if v is None else bool(v)
    n = d.get("n_trials")
    return Summary(method=str(d.get("method", "?")), group=str(d.get("group", "session")), angle_deg=_angle_of(d),
                   kind=str(d.get("kind", "")), n_trials=None if n is None else int(n),
                   D=_mat(d.get("D_Nspm")), K=_mat(d.get("K_Npm")), D_spread=_mat(d.get("D_spread")),
                   K_spread=_mat(d.get("K_spread")), D_lo=_mat(d.get("D_ci95_lo")), D_hi=_mat(d.get("D_ci95_hi")),
                   K_lo=_mat(d.get("K_ci95_lo")), K_hi=_mat(d.get("K_ci95_hi")),
                   identifiable=b(d.get("identifiable")), flag=str(d.get("flag") or ""), raw=d)


def parse_results(doc: dict, path: str = "<json>") -> Results:
    sessions = []
    for s in doc.get("sessions", []) or []:
        sums = [_summary(x) for x in (s.get("summaries") or [])]
        # A separate typed per-angle list, if a later layout has one (entries with numeric angle_deg).
        for key in ("per_angle", "angles", "per_angle_summaries"):
            for x in (s.get(key) or []) if isinstance(s.get(key), list) else []:
                if isinstance(x, dict):
                    y = dict(x)
                    if "group" not in y and isinstance(y.get("angle_deg"), (int, float)):
                        y["group"] = "angle %g" % y["angle_deg"]
                    sums.append(_summary(y))
        # Older/other layouts: session_summary only.
        if not sums and isinstance(s.get("session_summary"), dict):
            for m, x in s["session_summary"].items():
                sums.append(_summary(dict(x, method=m, group="session")))
        cu = s.get("cutoff_used_hz")
        sessions.append(SessionResult(
            log=str(s.get("log", "")), session=s.get("session") or {}, settings=s.get("settings") or {},
            cutoff_used_hz=None if cu is None else float(cu), counts=s.get("counts") or {}, summaries=sums,
            trials=list(s.get("trials") or []), psd=s.get("psd") or {}, truth=s.get("truth"),
            issues=list(s.get("issues") or []), warnings=[str(w) for w in (s.get("warnings") or [])], raw=s))
    dm = doc.get("default_method") or (doc.get("settings") or {}).get("default_method") or DEFAULT_METHOD
    return Results(path=path, version=str(doc.get("manip_version", "")), settings=doc.get("settings") or {},
                   sessions=sessions, default_method=str(dm), raw=doc)


def load_results(path: str) -> Results:
    with open(path, encoding="utf-8") as f:
        doc = json.load(f)
    return parse_results(doc, path)


# --------------------------------------------------------------------------- signals
SIGNAL_PAIRS = {  # signal -> (column stem, unit suffix)
    "dx": ("dx", "m"), "dxd": ("dxd", "mps"), "dxdd": ("dxdd", "mps2"),
    "du_ext": ("du_ext_adm", "n"), "du_ext_force": ("du_ext_force", "n"), "u_pert": ("u_pert", "n"),
    "dx_true": ("dx_true", "m"), "dxd_true": ("dxd_true", "mps"), "dxdd_true": ("dxdd_true", "mps2"),
    "du_ext_true": ("du_ext_true", "n"),
}


def load_signal_file(path: str) -> Dict[str, np.ndarray]:
    """One ``trial_<k>.csv``: ``{'t_s': (n,), 'dx': (n,2), ...}`` (and every raw column)."""
    with open(path, newline="") as f:
        header = next(csv.reader(f))
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    cols = {h.strip(): data[:, i] for i, h in enumerate(header)}
    out: Dict[str, np.ndarray] = dict(cols)
    for name, (stem, unit) in SIGNAL_PAIRS.items():
        a, b = "%s1_%s" % (stem, unit), "%s2_%s" % (stem, unit)
        if a in cols and b in cols:
            out[name] = np.column_stack([cols[a], cols[b]])
    return out


def load_signals(directory: str) -> Dict[int, Dict[str, np.ndarray]]:
    """All ``trial_<k>.csv`` of an ``--export-signals`` directory, by trial index."""
    out = {}
    for p in glob.glob(os.path.join(directory, "trial_*.csv")):
        m = re.search(r"trial_(\d+)\.csv$", p)
        if m:
            out[int(m.group(1))] = load_signal_file(p)
    return dict(sorted(out.items()))
