#!/usr/bin/env python3
"""manip_sim never destroys an existing log unless told (issue 9 item 7).

    sim_output_safety.py MANIP_SIM_BINARY

Before the fix `manip_sim --out p.lcm` overwrote p.lcm silently, and a
refused run could leave it empty. Checked here, each in a fresh directory:
  1. existing target, no --force        -> exit 6, target byte-identical, no temporary left
  2. existing target, --force, refused  -> exit 2, target byte-identical, no temporary left
     session design (24 perturbed trials in 5 movements)
  3. existing target, --force, good run -> exit 0, target replaced by an LCM log
     (first event's sync word 0xEDA1DA01), no temporary left, mode follows the umask
  4. new target, no --force             -> exit 0, written
"""
import os
import stat
import subprocess
import sys
import tempfile

# No -q: the flags an old manip_sim also knew, so case 1 fails on the clobber itself before the fix.
SHORT = ["--movements", "10", "--reps", "1"]
OLD = b"an earlier session that must survive\n"
LCM_SYNC = bytes.fromhex("EDA1DA01")


def case(binary, name, args, pre_existing, want_rc, want_replaced):
    with tempfile.TemporaryDirectory(prefix="manip_sim_safety_") as d:
        target = os.path.join(d, "p.lcm")
        if pre_existing:
            with open(target, "wb") as f:
                f.write(OLD)
        r = subprocess.run([binary, "--out", target] + args, cwd=d, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, timeout=300)
        problems = []
        if r.returncode != want_rc:
            problems.append("exit %d, want %d (stderr: %s)" % (r.returncode, want_rc, r.stderr.strip()))
        data = open(target, "rb").read() if os.path.exists(target) else None
        if want_replaced:
            if data is None or not data.startswith(LCM_SYNC):
                problems.append("target is not a fresh LCM log")
            else:
                mode = stat.S_IMODE(os.stat(target).st_mode)
                if mode & 0o044 != 0o044 & ~0o022:  # umask 022 in CI: group/other may read
                    problems.append("target mode %o (a session log must be readable like any new file)" % mode)
        elif pre_existing and data != OLD:
            problems.append("existing target changed: %d bytes now (was %d)" % (-1 if data is None else len(data), len(OLD)))
        if r.returncode != 0 and not r.stderr.strip():
            problems.append("refused without a message")
        leftovers = [f for f in os.listdir(d) if f != "p.lcm"]
        if leftovers:
            problems.append("left behind: %s" % leftovers)
        print("%s %s" % ("FAIL" if problems else "ok  ", name) + ("".join("\n     " + p for p in problems)))
        return not problems


def main():
    binary = os.path.abspath(sys.argv[1])
    os.umask(0o022)
    results = [
        case(binary, "existing target, no --force: exit 6, untouched", SHORT, True, 6, False),
        case(binary, "existing target, --force, refused design: exit 2, untouched",
             ["--movements", "5", "--force"], True, 2, False),
        case(binary, "existing target, --force, good run: replaced", SHORT + ["--force"], True, 0, True),
        case(binary, "new target: written", SHORT, False, 0, True),
    ]
    return 0 if all(results) else 1


if __name__ == "__main__":
    sys.exit(main())
