"""Simulated sessions for the integration tests (ctest fixture python:fixtures).

    python -m tests.make_fixtures OUTDIR

OUTDIR/session/: s.lcm (40 movements, seed 3; val/ = manip_sim --validate), s.json (--method all),
sig/ (--export-signals). OUTDIR/group/: p1..p5.lcm/.json, five participants
with different seeds and people (table1 / stiff presets). Reuses outputs
whose stamp matches the command lines and the apps' modification times.
Fails (exit 1) when the apps are not built: the tests need them.
"""
import json
import os
import subprocess
import sys

BUILD = os.environ.get("MANIP_BUILD_DIR", os.path.join(os.path.dirname(__file__), "..", "..", "build"))
SIM = os.path.join(BUILD, "apps", "manip_sim")
EST = os.path.join(BUILD, "apps", "estimate_impedance")
GROUP = [("p1", 11, "table1"), ("p2", 12, "stiff"), ("p3", 13, "table1"), ("p4", 14, "stiff"), ("p5", 15, "table1")]


def run(cmd, ok=(0,)):
    print("+", " ".join(cmd), flush=True)
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if r.returncode not in ok:
        sys.stderr.write(r.stdout[-4000:] + r.stderr[-4000:])
        raise SystemExit("%s failed with exit code %d" % (cmd[0], r.returncode))
    return r


def cached(out_dir, cmds, make):
    stamp = os.path.join(out_dir, "stamp.json")
    key = {"cmds": cmds, "apps": [os.path.getmtime(SIM), os.path.getmtime(EST)]}
    try:
        with open(stamp) as f:
            if json.load(f) == key:
                print("fixture %s up to date" % out_dir)
                return
    except (OSError, ValueError):
        pass
    os.makedirs(out_dir, exist_ok=True)
    make()
    with open(stamp, "w") as f:
        json.dump(key, f)


def main(out):
    if not (os.access(SIM, os.X_OK) and os.access(EST, os.X_OK)):
        print("apps not built (%s, %s): build manip_sim_app and estimate_impedance" % (SIM, EST), file=sys.stderr)
        return 1
    sdir = os.path.join(out, "session")
    s_cmds = [[SIM, "--force", "--out", os.path.join(sdir, "s.lcm"), "--movements", "40", "--seed", "3",
               "--validate", os.path.join(sdir, "val")],
              [EST, os.path.join(sdir, "s.lcm"), "--method", "all", "--json", os.path.join(sdir, "s.json"),
               "--export-signals", os.path.join(sdir, "sig"), "-q", "--force"]]

    def make_session():
        run(s_cmds[0])
        run(s_cmds[1], ok=(0, 1))   # 1: estimated, some fit flagged (expected per angle)
    cached(sdir, s_cmds, make_session)

    gdir = os.path.join(out, "group")
    g_cmds = []
    for name, seed, person in GROUP:
        lcm = os.path.join(gdir, name + ".lcm")
        g_cmds.append([SIM, "--force", "--out", lcm, "--movements", "40", "--seed", str(seed), "--person", person])
        g_cmds.append([EST, lcm, "--method", "all", "--json", os.path.join(gdir, name + ".json"), "-q", "--force"])

    def make_group():
        for i, c in enumerate(g_cmds):
            run(c, ok=(0,) if i % 2 == 0 else (0, 1))
            if i % 2 == 1:
                os.remove(c[1])   # ~230 MB per log; the group tests need the JSON only
    cached(gdir, g_cmds, make_group)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else os.environ["MANIP_PY_FIXTURES"]))
