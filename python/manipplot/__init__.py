"""manipplot: load manip logs, estimator results and exported signals into
numpy arrays; draw the paper's figures with matplotlib; write session reports
and group tables.

Modules
-------
io        logs (lcm.EventLog + generated manip types), results JSON, signals CSV
analysis  jerk PSDs (Fig. 3), NRMSE(dt) (Fig. 4), directional impedance, group statistics
figures   matplotlib figures (Fig. 3, 4, 5, directional D/K per angle, Table 1)
tables    text tables that never fuse, tidy CSV, JSON
report    ``python3 -m manipplot.report RESULTS.json ... -o report.html``
plots     ``python3 -m manipplot.plots RESULTS.json ... -o DIR``
group     ``python3 -m manipplot.group A.json B.json ... [--csv F] [--json F]``

Units are SI throughout (m, s, N, N s/m, N/m, kg); angles in degrees in
tables, radians in logs. Matrices are 2x2 in the shoulder frame, row-major
[11, 12, 21, 22] (docs/conventions.md).
"""

__version__ = "0.1.0"
