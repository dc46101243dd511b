#!/usr/bin/env bash
# Estimator benchmark (docs/benchmarks.md, "## Estimator"): decode floor, end to end,
# processing alone (C++ vs the SciPy reference), peak RSS of estimate_impedance.
#
#   bench/run_estimator_bench.sh [--reps N] [--py-reps N] [--decode-reps N] [--no-build] [--keep-log]
#
# Environment: BUILD (default build-bench), OUT (default /tmp/bench), PY (default .venv/bin/python).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
BUILD=${BUILD:-build-bench}
OUT=${OUT:-/tmp/bench}
PY=${PY:-$ROOT/.venv/bin/python}
REPS=5
PY_REPS=3
DECODE_REPS=1
BUILD_IT=1
MOVEMENTS=100
while [[ $# -gt 0 ]]; do
  case $1 in
    --reps) REPS=$2; shift 2 ;;
    --py-reps) PY_REPS=$2; shift 2 ;;
    --decode-reps) DECODE_REPS=$2; shift 2 ;;
    --movements) MOVEMENTS=$2; shift 2 ;;
    --no-build) BUILD_IT=0; shift ;;
    *) echo "unknown argument $1" >&2; exit 2 ;;
  esac
done

if [[ $BUILD_IT == 1 ]]; then
  cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
  ninja -C "$BUILD" bench_estimator manip_sim_app estimate_impedance >/dev/null
fi
SIM=$BUILD/apps/manip_sim
[[ -x $SIM ]] || SIM=$(find "$BUILD" -name manip_sim -type f -perm -u+x | head -1)
EST=$BUILD/apps/estimate_impedance
[[ -x $EST ]] || EST=$(find "$BUILD" -name estimate_impedance -type f -perm -u+x | head -1)

mkdir -p "$OUT"
LOG=$OUT/session.lcm
if [[ ! -s $LOG ]]; then
  echo "generating $LOG ($MOVEMENTS movements, realistic noise)" >&2
  "$SIM" --out "$LOG" --movements "$MOVEMENTS" --noise realistic >/dev/null
fi
ls -l "$LOG" >&2

# The machines are shared: record how busy this one was around the run.
echo "load before: $(cut -d' ' -f1-3 /proc/loadavg)" | tee "$OUT/load.txt" >&2
echo "== C++ ($REPS reps, interleaved)" >&2
"$BUILD/bench/bench_estimator" "$LOG" --reps "$REPS" | tee "$OUT/cpp.txt"

echo "== SciPy reference ($PY_REPS processing reps, $DECODE_REPS decode reps)" >&2
"$PY" bench/scipy_reference.py "$LOG" --python-types "$BUILD/python" --reps "$PY_REPS" \
  --decode-reps "$DECODE_REPS" | tee "$OUT/py.txt"

echo "== peak RSS of estimate_impedance (3 runs per method)" >&2
: >"$OUT/rss.txt"
for m in paper pem oe; do
  for _ in 1 2 3; do
    /usr/bin/time -f "RSS $m %M %e" "$EST" "$LOG" --method "$m" -q >/dev/null 2>>"$OUT/rss.txt" || true
  done
done
grep '^RSS' "$OUT/rss.txt" >&2
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)" | tee -a "$OUT/load.txt" >&2

# Table.
"$PY" - "$OUT/cpp.txt" "$OUT/py.txt" "$OUT/rss.txt" <<'EOF'
import re, statistics, sys
r = {}
for f in sys.argv[1:3]:
    for line in open(f):
        m = re.match(r"RESULT (\S+) median_s=(\S+) min_s=(\S+) max_s=(\S+) reps=(\d+)", line)
        if m:
            r[m.group(1)] = tuple(float(x) for x in m.group(2, 3, 4)) + (int(m.group(5)),)
rss = {}
for line in open(sys.argv[3]):
    if line.startswith("RSS "):
        _, meth, kb, sec = line.split()
        rss.setdefault(meth, []).append((int(kb) / 1024, float(sec)))
rows = [
    ("floor", "C++ read_log + decode only"),
    ("e2e-paper", "C++ estimate_log, methods {paper}"),
    ("e2e-default", "C++ estimate_log, default methods {pem}"),
    ("proc-paper", "C++ SessionEstimator on in-memory trials, {paper}"),
    ("proc-default", "C++ SessionEstimator on in-memory trials, {pem} (default)"),
    ("py-decode", "Python lcm.EventLog read + decode + trial arrays"),
    ("py-proc-full", "SciPy chain, paper method (SG d=1,2,3 as briefed)"),
    ("py-proc-minimal", "SciPy chain, paper method (SG d=3 only, as C++)"),
    ("floor-cpu", "(CPU time) floor"),
    ("e2e-paper-cpu", "(CPU time, both threads) e2e {paper}"),
    ("proc-paper-cpu", "(CPU time) C++ processing {paper}"),
    ("py-proc-full-cpu", "(CPU time) SciPy chain, full"),
    ("py-proc-minimal-cpu", "(CPU time) SciPy chain, minimal"),
]
print()
print("| measurement | median [s] | min [s] | max [s] | reps |")
print("|---|---:|---:|---:|---:|")
for k, label in rows:
    if k in r:
        med, lo, hi, n = r[k]
        print(f"| {label} (`{k}`) | {med:.3f} | {lo:.3f} | {hi:.3f} | {n} |")
for meth, v in rss.items():
    mb = [x[0] for x in v]
    print(f"| estimate_impedance --method {meth}: peak RSS [MB], wall [s] | {statistics.median(mb):.0f} MB | "
          f"{min(mb):.0f} MB | {max(mb):.0f} MB | {len(v)} (wall median {statistics.median(x[1] for x in v):.2f} s) |")
print()
def ratio(a, b, label, target):
    if a in r and b in r:
        q = r[a][0] / r[b][0]
        print(f"- {label}: {q:.2f} (target {target})")
ratio("e2e-paper", "floor", "end-to-end {paper} / floor", "<= 1.5")
ratio("e2e-default", "floor", "end-to-end {pem} (default) / floor", "<= 1.5")
ratio("py-proc-full", "proc-paper", "SciPy processing (full) / C++ processing {paper}", ">= 10")
ratio("py-proc-minimal", "proc-paper", "SciPy processing (minimal) / C++ processing {paper}", ">= 10")
ratio("py-decode", "floor", "Python read+decode / C++ floor", "info")
ratio("e2e-paper-cpu", "floor-cpu", "(CPU time) end-to-end {paper} / floor", "info: what a fully loaded machine would show")
ratio("py-proc-full-cpu", "proc-paper-cpu", "(CPU time) SciPy processing (full) / C++ processing {paper}", "info")
ratio("py-proc-minimal-cpu", "proc-paper-cpu", "(CPU time) SciPy processing (minimal) / C++ processing {paper}", "info")
if rss:
    worst = max(x[0] for v in rss.values() for x in v)
    print(f"- peak RSS of estimate_impedance: {worst:.0f} MB max over runs (target < 256 MB)")
EOF
