#!/usr/bin/env python3
"""Compile every source of the tree alone: clang, front end only.

CI and the README's commands build unity builds (CMake's CMAKE_UNITY_BUILD:
up to 8 sources of a target in one compile), where a source can use a
header that only an earlier source of its batch included. This check
compiles each source on its own, as a one-file build would, with clang's
front end only (-fsyntax-only: parsing, templates instantiated, every
warning of the build, -Werror; no optimisation, no object): about 2 min of
wall time on the 2-core machine, about 40 s more than the 94 s the unity
build saves (docs/benchmarks.md, "Unity Release build"), kept because it is
also the tree's only clang compile of every source (the fuzz build compiles
the harnesses' share).

    scripts/compile_alone.py [--build DIR] [--jobs N] [SOURCE_PREFIX ...]

Configures DIR (default build-alone/) with clang, one file per compile,
generates the LCM headers, then runs each compile command of
DIR/compile_commands.json whose source path (relative to the tree) starts
with one of the prefixes (all by default). Exit 0 when every source
compiles, 1 when any does not (one line per source on stderr, then its
diagnostics), 2 on a set-up failure (cmake or the header generation).
"""
import argparse
import json
import os
import shlex
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def configure(build):
    cmd = ["cmake", "-S", ROOT, "-B", build, "-G", "Ninja", "-DCMAKE_BUILD_TYPE=Release",
           "-DCMAKE_C_COMPILER=clang", "-DCMAKE_CXX_COMPILER=clang++", "-DMANIP_WERROR=ON",
           "-DCMAKE_UNITY_BUILD=OFF", "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON"]
    for step in (cmd, ["ninja", "-C", build, "manip_lcmtypes_gen"]):
        r = subprocess.run(step, capture_output=True, text=True)
        if r.returncode != 0:
            sys.stderr.write(r.stdout + r.stderr)
            sys.stderr.write(f"compile_alone: set-up failed: {' '.join(step)} (exit {r.returncode})\n")
            sys.exit(2)


def front_end_only(command):
    """The compile command with -fsyntax-only and without its object output."""
    args, out, skip = shlex.split(command), [], False
    for a in args:
        if skip:
            skip = False
        elif a == "-o":
            skip = True
        elif a != "-c":
            out.append(a)
    return out + ["-fsyntax-only"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build", default=os.path.join(ROOT, "build-alone"))
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("prefixes", nargs="*")
    a = ap.parse_args()
    build = os.path.abspath(a.build)
    configure(build)
    with open(os.path.join(build, "compile_commands.json")) as f:
        entries = json.load(f)
    todo = []
    for e in entries:
        rel = os.path.relpath(e["file"], ROOT)
        if not a.prefixes or any(rel.startswith(p) for p in a.prefixes):
            todo.append((rel, e))

    def run(item):
        rel, e = item
        r = subprocess.run(front_end_only(e["command"]), cwd=e["directory"], capture_output=True, text=True)
        return rel, r.returncode, r.stderr

    t0 = time.monotonic()
    with ThreadPoolExecutor(max(1, a.jobs)) as ex:
        results = list(ex.map(run, todo))
    failed = [(rel, err) for rel, rc, err in results if rc != 0]
    for rel, err in failed:
        first = next((l for l in err.splitlines() if "error" in l), "no diagnostic")
        sys.stderr.write(f"compile_alone: {rel}: does not compile alone: {first}\n")
    for rel, err in failed:
        sys.stderr.write(f"--- {rel}\n{err}")
    print(f"compile_alone: {len(results) - len(failed)}/{len(results)} sources compile alone "
          f"(clang -fsyntax-only, {time.monotonic() - t0:.0f} s, {a.jobs} jobs)", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
