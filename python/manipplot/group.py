"""Group table over participants (paper Table 1: mean (std) over participants).

    python3 -m manipplot.group RESULTS.json [RESULTS.json ...] [--method pem]
                               [--csv FILE] [--json FILE] [--split-by-settings]

Every session of every RESULTS.json is one participant (its session's
participant_id, or the log's file name). Sessions estimated with different
settings are refused (exit 2, the differing keys named) unless
--split-by-settings, which prints one table per configuration. The text table
goes to stdout; --csv writes the tidy long form (one row per participant or
group statistic and element, typed columns), --json the same numbers nested.
"""
from __future__ import annotations

import argparse
import json
import sys

from . import analysis as A
from . import tables as T
from .io import DEFAULT_METHOD, load_results


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m manipplot.group", description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="+", help="estimate_impedance --json outputs (one or more sessions each)")
    ap.add_argument("--method", action="append", help="method(s) (default: the default method, %s)" % DEFAULT_METHOD)
    ap.add_argument("--csv", help="tidy long-form CSV")
    ap.add_argument("--json", dest="json_out", help="JSON")
    ap.add_argument("--split-by-settings", action="store_true", help="one table per configuration instead of refusing")
    a = ap.parse_args(argv)
    try:
        res = [load_results(p) for p in a.results]
    except (OSError, ValueError) as e:
        print("manipplot.group: %s" % e, file=sys.stderr)
        return 2
    default = res[0].default_method if res else DEFAULT_METHOD
    sessions = A.collect_sessions(res)
    try:
        if a.split_by_settings:
            groups = A.split_by_settings(sessions)
        else:
            A.check_same_configuration(sessions)
            groups = [sessions]
        tables = [A.group_table(g, m) for g in groups for m in (a.method or [default])]
    except A.GroupError as e:
        print("manipplot.group: %s" % e, file=sys.stderr)
        return 2
    rows, docs = [], []
    for i, g in enumerate(tables):
        if len(groups) > 1:
            print("configuration %d of %d" % (i // len(a.method or [default]) + 1, len(groups)))
        print(T.group_text(g, default))
        rows += T.group_rows(g, default)
        docs.append(T.group_json(g, default))
    if a.csv:
        T.write_csv(a.csv, T.GROUP_COLUMNS, rows)
    if a.json_out:
        with open(a.json_out, "w", encoding="utf-8") as f:
            json.dump({"groups": docs}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
