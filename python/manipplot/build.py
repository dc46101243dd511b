"""Assemble every figure of one session from whatever inputs exist.

Inputs (all optional beyond the results): the LCM log (Fig. 3 PSDs, the
truth of Fig. 4/5), the exported signals (Fig. 4, Fig. 5), a ``manip_sim
--validate`` validation.json (Fig. 4 without log). What cannot be drawn is
reported as a note, never silently skipped.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Dict, List, Optional

from . import analysis as A
from . import figures as F
from . import tables as T
from .io import Log, Results, SessionResult, load_log, load_signals


@dataclass
class Inputs:
    session: SessionResult
    log: Optional[Log] = None
    signals: Dict[int, dict] = field(default_factory=dict)
    validation: Optional[dict] = None
    notes: List[str] = field(default_factory=list)


def resolve_inputs(res: Results, signals_dir: Optional[str], log_path: Optional[str],
                   validation_path: Optional[str] = None, load_logs: bool = True) -> List[Inputs]:
    """One :class:`Inputs` per session of ``res``; with several sessions the signals of
    session ``<stem>`` are looked up in ``signals_dir/<stem>`` (estimate_impedance's layout)
    and ``log_path`` may be a directory holding the logs."""
    import json
    out = []
    many = len(res.sessions) > 1
    val = None
    if validation_path:
        with open(validation_path, encoding="utf-8") as f:
            val = json.load(f)
    for s in res.sessions:
        inp = Inputs(session=s, validation=val)
        stem = os.path.splitext(os.path.basename(s.log))[0]
        lp = log_path
        if lp and os.path.isdir(lp):
            lp = os.path.join(lp, os.path.basename(s.log))
        if lp and load_logs:
            try:
                inp.log = load_log(lp)
            except Exception as e:  # named, not fatal
                inp.notes.append("log %s not read: %s" % (lp, e))
        elif not lp:
            inp.notes.append("no log given (--log): Fig. 3 needs the log or PSD arrays in the JSON; truth only from signals")
        if signals_dir:
            d = os.path.join(signals_dir, stem) if many and os.path.isdir(os.path.join(signals_dir, stem)) else signals_dir
            inp.signals = load_signals(d)
            if not inp.signals:
                inp.notes.append("no trial_<k>.csv in %s" % d)
        else:
            inp.notes.append("no signals given (--signals): Fig. 4 and Fig. 5 need estimate_impedance --export-signals")
        out.append(inp)
    return out


def session_figures(inp: Inputs, methods: Optional[List[str]] = None, all_trials: bool = False,
                    default_method: str = "pem") -> Dict[str, "F.Figure"]:
    """name -> Figure. Names: fig3_psd_jerk_x2, fig4_nrmse, fig5_trial_<k>,
    directional_<method>, table1_<method>."""
    s = inp.session
    figs = {}
    # Fig. 3
    p = A.psds_from_results(s)
    if p is None and inp.log is not None:
        try:
            excl = [int(i.get("trial", -1)) for i in s.issues]
            p = A.jerk_psds(inp.log, A.sg_window_of(s, inp.log.sample_rate_hz),
                            int(s.settings.get("sg_order", 5)), int(s.settings.get("psd_nfft", 65536)),
                            float(s.settings.get("cutoff_auto_threshold_db", 3.0)), excl)
        except ValueError as e:
            inp.notes.append("Fig. 3 not drawn: %s" % e)
    if p is not None:
        figs["fig3_psd_jerk_x2"] = F.fig_psd(p, s.cutoff_used_hz)
    elif inp.log is None:
        inp.notes.append("Fig. 3 not drawn: no log and no PSD arrays in the JSON")
    # Fig. 4
    c = None
    if inp.log is not None and inp.signals and inp.log.has_truth:
        c = A.nrmse_curves(inp.log, inp.signals, float(s.settings.get("t_est_s", 0.15)))
    elif inp.validation is not None and "nrmse" in inp.validation:
        c = A.nrmse_from_validation(inp.validation)
    if c is not None:
        figs["fig4_nrmse"] = F.fig_nrmse(c)
    else:
        inp.notes.append("Fig. 4 not drawn: needs twin truth (simulated log with --log, and --signals) "
                         "or a validation.json")
    # Fig. 5
    trials = list(inp.signals)[: (None if all_trials else 1)]
    angle = {int(t.get("trial", -1)): t.get("angle_deg") for t in s.trials}
    for k in trials:
        sig = inp.signals[k]
        tru = A.true_variations(inp.log, k, len(sig["t_s"])) if inp.log is not None else None
        a = angle.get(k)
        if a is None and inp.log is not None:
            a = next((t.angle_deg for t in inp.log.trials if t.index == k), None)
        figs["fig5_trial_%d" % k] = F.fig_variational(sig, tru, k, a)
    # directional per angle, Table 1
    for m in methods or s.methods():
        if s.per_angle(m):
            figs["directional_%s" % m] = F.fig_directional(s, m)
        summ = s.summary(m, "session")
        if summ is not None:
            marks = T.method_marks(m, default_method)
            figs["table1_%s" % m] = F.fig_table1(
                "%s, %s: estimate [95 %% interval]%s" % (s.participant, m, " (%s)" % marks if marks else ""),
                {k: v.replace(" [", "\n[", 1) for k, v in T.summary_cells(summ, 3).items()}, T.flag_text(summ))
    return figs
