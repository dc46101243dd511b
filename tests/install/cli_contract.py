#!/usr/bin/env python3
"""The CLI contract of one app (docs/cli.md), checked from outside.

    cli_contract.py SOURCE_DIR APP_BINARY [--returns [--sim MANIP_SIM]] [--help-only]

* `--help` exits 0 and prints "Exit codes (docs/exit-codes.md):" followed by
  rows "  <code> <name>" whose names equal common/exit_codes' names for those
  codes. The reference table is read independently of the binary, from
  include/manip/common/exit_codes.hpp (constant -> number) and
  src/common/exit_codes.cpp (constant -> name).
* `--version` exits 0 and prints exactly "<app> <project version>".
* `--help-only` (apps not yet on common/cli.hpp): `--help` exits 0 and every
  "N  text" row it prints uses a code of the one table.
* `--returns`: each documented code other than 70 (a bug) is produced by a
  known bad (or good) invocation (or several: ("ALL", case, ...)), so the table and the behaviour agree; a
  code that cannot be produced on this machine (9 on a PREEMPT_RT kernel) is
  named as skipped. A case may also require its stderr to match a pattern
  (manip_import: the mapping's file:line: key). The exit-0 case runs with -q and must print nothing on
  stderr (docs/cli.md: only warnings and errors). `--sim` gives manip_sim,
  which writes the logs estimate_impedance's cases read.
"""
import math
import os
import random
import re
import signal
import subprocess
import sys
import tempfile


def reference_table(src):
    hpp = open(os.path.join(src, "include/manip/common/exit_codes.hpp")).read()
    cpp = open(os.path.join(src, "src/common/exit_codes.cpp")).read()
    num = {k: int(v) for k, v in re.findall(r"inline constexpr int (k\w+) = (\d+);", hpp)}
    names = {num[k]: v for k, v in re.findall(r'case (k\w+): return "([^"]*)";', cpp)}
    if len(names) < 10:
        raise SystemExit("could not read the exit-code table from the sources")
    return names


def project_version(src):
    m = re.search(r"project\(manip VERSION (\S+)", open(os.path.join(src, "CMakeLists.txt")).read())
    return m.group(1)


def run(cmd, cwd, interrupt_after=None):
    """Runs cmd; with interrupt_after, sends SIGINT that many seconds after the start."""
    if interrupt_after is None:
        return subprocess.run(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=300)
    p = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        p.communicate(timeout=interrupt_after)
    except subprocess.TimeoutExpired:
        p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    return subprocess.CompletedProcess(cmd, p.returncode, out, err)


def preempt_rt():
    try:
        return open("/sys/kernel/realtime").read().strip() == "1"
    except OSError:
        return False


def printed_table(help_text):
    lines = help_text.splitlines()
    try:
        i = lines.index("Exit codes (docs/exit-codes.md):")
    except ValueError:
        return None
    rows = {}
    for line in lines[i + 1:]:
        m = re.match(r"^\s+(\d+) (\S.*)$", line)
        if not m:
            break
        rows[int(m.group(1))] = m.group(2)
    return rows


IMPORT_MAPPING = """time: {variable: t, unit: s}
signals:
  position: {variables: [x_mm, y_mm], unit: %s}
  handle_force: {variables: [fx, fy], unit: N}
  perturbation_force: {variables: [ux, uy], unit: N}
frame:
  axes: [2, -1]
  origin_in_shoulder_m: [0.0, 0.425]
  rotation_deg: 0
trials:
  index: {variable: trial, outside: -1}
  onset: {rule: threshold, threshold_n: 0.5}
session:
  participant_id: P01
  session_id: S1
  admittance: {m_adm_kg: [5, 5], d_adm_nspm: [15, 15]}
  m_handle_kg: [0.25, 0.25]
  anthropometrics:
    segment_length_m: [0.31, 0.34]
    segment_mass_kg: [1.93, 1.52]
    segment_com_m: [0.165, 0.19]
    segment_inertia_kgm2: [0.0141, 0.0188]
  perturbation: {duration_s: 0.15, amplitude_n: 15, trigger_x2_shoulder_m: 0.40}
"""


def import_cases(tmp, existing):
    """manip_import: a hand-made 1 kHz CSV recording (two trials, one push,
    as tests/importer), its mapping, and one broken variant of each."""
    rows = ["t,x_mm,y_mm,fx,fy,ux,uy,trial"]
    for i in range(4000):
        t = i / 1000.0
        u = 15.0 * math.sin(math.pi * (i - 3000) / 150.0) ** 2 if 3000 <= i <= 3150 else 0.0
        trial = 0 if 500 <= i < 2000 else 1 if 2200 <= i < 3800 else -1
        rows.append("%.6f,%.6f,%.6f,%.6f,-0.2,%.6f,%.6f,%d" % (
            t, 100.0 + 10.0 * math.sin(t), -50.0 + 80.0 * t, 0.1 * t, -u * math.sin(math.radians(120)),
            u * math.cos(math.radians(120)), trial))
    good_csv, bad_csv = os.path.join(tmp, "rec.csv"), os.path.join(tmp, "bad_rec.csv")
    with open(good_csv, "w") as f:
        f.write("\n".join(rows) + "\n")
    rows[17] = rows[17].replace("-0.2", "abc", 1)   # line 18 of the file: not a number
    with open(bad_csv, "w") as f:
        f.write("\n".join(rows) + "\n")
    good_map, bad_map = os.path.join(tmp, "rig.yaml"), os.path.join(tmp, "bad_rig.yaml")
    with open(good_map, "w") as f:
        f.write(IMPORT_MAPPING % "mm")
    with open(bad_map, "w") as f:
        f.write(IMPORT_MAPPING % "inch")   # line 3: signals.position.unit
    out = lambda name: ["--out", os.path.join(tmp, name)]
    return {
        0: [good_map, good_csv, "-q"] + out("imported.lcm"),
        2: [good_map, good_csv],   # --out is required
        # docs/import.md, "Errors": the mapping's file, line and key are named.
        3: ("STDERR", re.escape(bad_map) + r":3: signals\.position\.unit: unknown unit 'inch'",
            [bad_map, good_csv] + out("never.lcm")),
        4: ("STDERR", re.escape(bad_csv) + r":18: column 'fy': not a number", [good_map, bad_csv] + out("never.lcm")),
        6: ("STDERR", re.escape(existing) + r": exists", [good_map, good_csv, "--out", existing]),
    }


def single_joint_csv(path, seconds):
    """diagnose_model: a single-joint record (docs/diagnosis.md: '# dt=' and
    pos_rad, torque_nm), torque = I acc + B vel + K pos + c + noise from a sum
    of sines; 12 s is enough for 3 folds."""
    rnd = random.Random(7)
    comps = [(rnd.uniform(0.5, 12.0), rnd.uniform(0.0, 6.3), rnd.uniform(0.005, 0.02)) for _ in range(12)]
    rows = ["# dt=0.001"]
    for i in range(int(seconds * 1000)):
        t = i * 0.001
        p = v = a = 0.0
        for f, ph, amp in comps:
            w = 2.0 * math.pi * f
            p += amp * math.sin(w * t + ph)
            v += amp * w * math.cos(w * t + ph)
            a -= amp * w * w * math.sin(w * t + ph)
        rows.append("%.9f,%.6f" % (p, 0.02 * a + 0.8 * v + 30.0 * p + 0.5 + rnd.gauss(0.0, 0.05)))
    with open(path, "w") as f:
        f.write("\n".join(rows) + "\n")


def diagnose_cases(tmp, existing):
    good, bad = os.path.join(tmp, "sj.csv"), os.path.join(tmp, "bad_sj.csv")
    single_joint_csv(good, 12.0)
    with open(bad, "w") as f:
        f.write("# dt=0.001\n0.1,0.2\n0.1,abc\n")
    fast = ["--folds", "3", "--bootstrap", "20"]
    return {
        0: ["--single-joint", good, "-q", "--json", os.path.join(tmp, "report.json")] + fast,
        2: ["--single-joint", good, "--folds", "2"],
        4: ("STDERR", re.escape(bad) + r":3: field 2 is not a finite number", ["--single-joint", bad] + fast),
        # docs/cli.md: an existing output is kept; refused before the record is read.
        6: ("STDERR", re.escape(existing) + r": exists", ["--single-joint", good, "--json", existing] + fast),
    }


def returns_cases(app, src, tmp, sim=None):
    """code -> argv producing it (run in tmp), or ("SIGINT", seconds, argv), or ("SKIP", reason).
    Only codes an app documents are used."""
    bus = os.path.join(src, "tests/canopen/bus.yml")
    bad_yaml = os.path.join(tmp, "bad.yaml")
    with open(bad_yaml, "w") as f:
        f.write("integration:\n  step_s: [1\n")
    existing = os.path.join(tmp, "existing.out")
    with open(existing, "w") as f:
        f.write("keep\n")
    # manip_rt: a configuration whose velocity limit a normal reach exceeds (safety fault).
    slow_yaml = os.path.join(tmp, "slow_rt.yaml")
    rt_yaml = open(os.path.join(src, "config", "rt.yaml")).read()
    rt_yaml, n = re.subn(r"max_velocity_mps: *[0-9.]+", "max_velocity_mps: 0.02", rt_yaml)
    assert n == 1, "config/rt.yaml has no max_velocity_mps"
    with open(slow_yaml, "w") as f:
        f.write(rt_yaml)
    # Paced and long (60 s) for the SIGINT case, with the overrun limits
    # relaxed so a loaded machine cannot turn it into a fault: a fixed-time
    # signal into an as-fast-as-possible session arrives after its end on a
    # fast machine (CI finished a whole default session within 1.5 s).
    paced_yaml = os.path.join(tmp, "paced_rt.yaml")
    paced, n = re.subn(r"overrun_fault_(consecutive|per_second): *[0-9]+", r"overrun_fault_\1: 100000",
                       open(os.path.join(src, "config", "rt.yaml")).read())
    assert n == 2, "config/rt.yaml has no overrun_fault_* limits"
    with open(paced_yaml, "w") as f:
        f.write(paced)
    rt_log = lambda name: ["--out", os.path.join(tmp, name)]
    # estimate_impedance: logs written by manip_sim (--sim).
    est = {}
    if app == "estimate_impedance" and sim:
        good, none_perturbed = os.path.join(tmp, "good.lcm"), os.path.join(tmp, "unperturbed.lcm")
        subprocess.run([sim, "--movements", "10", "--reps", "1", "--seed", "3", "-q", "--out", good], check=True)
        subprocess.run([sim, "--movements", "3", "--reps", "0", "-q", "--out", none_perturbed], check=True)
        # Cut inside the last trial: that trial is excluded, the rest estimated (partial).
        cut = os.path.join(tmp, "cut.lcm")
        data = open(good, "rb").read()
        with open(cut, "wb") as f:
            f.write(data[:len(data) * 95 // 100])
        est = {
            0: [good, "-q"],
            1: [cut, "-q"],
            2: [good, "--t-est", "nan"],
            3: [good, "--config", bad_yaml],
            4: [os.path.join(tmp, "missing.lcm")],
            5: [none_perturbed],
            6: [good, "--json", existing],
        }
    imp = import_cases(tmp, existing) if app == "manip_import" else {}
    diag = diagnose_cases(tmp, existing) if app == "diagnose_model" else {}
    cases = {
        "manip_sim": {
            0: ["--out", os.path.join(tmp, "s.lcm"), "--movements", "10", "--reps", "1", "-q"],
            2: ["--noise", "loud"],
            3: ["--human", "neuromech", "--config", bad_yaml, "--out", os.path.join(tmp, "n.lcm")],
            6: ["--out", existing, "--movements", "10", "--reps", "1"],
        },
        "impedance_study": {
            0: ["--sessions", "1", "--persons", "table1", "--noise", "none", "--methods", "paper", "-q",
                "--out", os.path.join(tmp, "t.md")],
            2: ["--persons", "table1,stif"],
            6: ["--json", existing, "--sessions", "1"],
        },
        "manip_can_check": {
            0: ["--config", bus, "--virtual", "--periods", "200", "-q"],
            2: ["--periods", "nan"],
            3: ["--config", os.path.join(tmp, "missing.yml"), "--virtual"],
            8: ["--config", bus, "--virtual", "--virtual-fault", "never-boot", "--periods", "200"],
        },
        "manip_rt": {
            0: ["--movements", "1", "--lcm-url", "none", "-q"] + rt_log("rt.lcm"),
            2: ["--movements", "0"] + rt_log("never.lcm"),
            3: ["--config", bad_yaml] + rt_log("never.lcm"),
            6: ["--movements", "1", "--lcm-url", "none", "--out", existing],
            7: ["--config", slow_yaml, "--movements", "1", "--lcm-url", "none"] + rt_log("fault.lcm"),
            # The default can.yaml names can0: absent (or no AF_CAN at all) on a CI machine.
            8: ["--backend", "can", "--lcm-url", "none"] + rt_log("can.lcm"),
            9: ("SKIP", "this kernel is PREEMPT_RT: --require-rt may succeed") if preempt_rt() else
               ["--realtime", "--require-rt", "--duration", "0.1", "--lcm-url", "none"] + rt_log("never.lcm"),
            10: ["--realtime", "--duration", "1", "--lcm-url", "nosuch://x"] + rt_log("bus.lcm"),
            130: ("SIGINT", 1.0, ["--config", paced_yaml, "--realtime", "--duration", "60", "--lcm-url", "none",
                                  "--force"] + rt_log("int.lcm")),
        },
        "estimate_impedance": est,
        "manip_import": imp,
        "diagnose_model": diag,
        "make_hidden_session": {
            0: ["--movements", "8", "--reps", "1", "-q", "--out", os.path.join(tmp, "h.lcm"),
                "--key", os.path.join(tmp, "h.key")],
            2: ("STDERR", r"--hidden 'bogus:1': unknown mechanism", ["--hidden", "bogus:1", "--movements", "8",
                                                                     "--reps", "1", "--out", os.path.join(tmp, "never.lcm")]),
            # Both outputs: an existing --out or --key is kept and refused before the session runs.
            6: ("ALL", ("STDERR", re.escape(existing) + r": exists", ["--movements", "8", "--reps", "1", "--out", existing]),
                ("STDERR", re.escape(existing) + r": exists",
                 ["--movements", "8", "--reps", "1", "--out", os.path.join(tmp, "never.lcm"), "--key", existing])),
        },
        "manip_fake_drive": {
            2: ["--mass-kg", "inf"],
            # No such interface (on this kernel possibly no AF_CAN at all): the backend is unavailable.
            8: ["--iface", "manipnosuchcan0", "--duration", "0.01", "-q"],
        },
    }
    return cases.get(app, {})


def main():
    src, binary = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
    check_returns = "--returns" in sys.argv[3:]
    app = os.path.basename(binary)
    ref = reference_table(src)
    failures = []
    if "--help-only" in sys.argv[3:]:
        h = run([binary, "--help"], os.getcwd())
        codes = [int(c) for c in re.findall(r"^\s+(\d+)\s+[a-zA-Z(]", h.stdout, re.M)]
        if h.returncode != 0:
            failures.append("--help exited %d" % h.returncode)
        if not codes:
            failures.append("--help prints no exit-code rows")
        for c in codes:
            if c not in ref:
                failures.append("--help documents exit code %d, not in common/exit_codes" % c)
        for f in failures:
            print("FAIL %s: %s" % (app, f))
        if not failures:
            print("OK %s: --help exits 0, rows use codes %s of the one table" % (app, codes))
        return 1 if failures else 0
    with tempfile.TemporaryDirectory(prefix="manip_cli_%s_" % app) as tmp:
        h = run([binary, "--help"], tmp)
        if h.returncode != 0:
            failures.append("--help exited %d" % h.returncode)
        rows = printed_table(h.stdout)
        if rows is None:
            failures.append("--help prints no 'Exit codes (docs/exit-codes.md):' table")
            rows = {}
        for code, name in rows.items():
            if ref.get(code) != name:
                failures.append("--help row %d '%s' != common/exit_codes '%s'" % (code, name, ref.get(code)))
        for must in (0, 2):
            if rows and must not in rows:
                failures.append("--help table lacks code %d" % must)
        v = run([binary, "--version"], tmp)
        want = "%s %s" % (app, project_version(src))
        if v.returncode != 0 or v.stdout.strip() != want:
            failures.append("--version: exit %d, printed %r (want %r)" % (v.returncode, v.stdout.strip(), want))
        if check_returns:
            sim = sys.argv[sys.argv.index("--sim") + 1] if "--sim" in sys.argv else None
            cases = returns_cases(app, src, tmp, sim)
            existing_path = os.path.join(tmp, "existing.out")   # written by returns_cases: "keep"
            if not cases:
                failures.append("no return-code cases known for %s" % app)
            # A code maps to one case, or to a list of cases ("ALL", case, case, ...).
            flat = []
            for code, case in sorted(cases.items()):
                if code not in rows:
                    failures.append("case for code %d, which --help does not document" % code)
                if isinstance(case, tuple) and case[0] == "ALL":
                    flat += [(code, c) for c in case[1:]]
                else:
                    flat.append((code, case))
            for code, case in flat:
                interrupt, want_err = None, None
                if isinstance(case, tuple) and case[0] == "SKIP":
                    print("SKIP %s: code %d: %s" % (app, code, case[1]))
                    continue
                if isinstance(case, tuple) and case[0] == "SIGINT":
                    interrupt, args = case[1], case[2]
                elif isinstance(case, tuple) and case[0] == "STDERR":
                    want_err, args = case[1], case[2]
                else:
                    args = case
                r = run([binary] + args, tmp, interrupt)
                if r.returncode != code:
                    failures.append("%s -> exit %d, want %d (%s); stderr: %s" % (
                        " ".join(args), r.returncode, code, ref.get(code), r.stderr.strip()[-300:]))
                elif code != 0 and not (r.stderr.strip() or r.stdout.strip()):
                    failures.append("%s -> exit %d without a message" % (" ".join(args), code))
                elif want_err and not re.search(want_err, r.stderr):
                    failures.append("%s -> exit %d but stderr does not match %r: %s" % (
                        " ".join(args), code, want_err, r.stderr.strip()[-300:]))
                elif existing_path in args and open(existing_path).read() != "keep\n":
                    failures.append("%s -> exit %d and the existing output was changed" % (" ".join(args), code))
                elif code == 0 and ("-q" in args or "--quiet" in args) and r.stderr.strip():
                    failures.append("%s -> exit 0 but -q printed on stderr: %s" % (" ".join(args), r.stderr.strip()[-300:]))
            undocumented = sorted(set(rows) - set(cases) - {0, 70})
            if undocumented:
                failures.append("documented codes without a case: %s" % undocumented)
    for f in failures:
        print("FAIL %s: %s" % (app, f))
    if failures:
        return 1
    print("OK %s: --help table %s, --version '%s'%s" % (
        app, sorted(rows), want, ", return codes checked" if check_returns else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
