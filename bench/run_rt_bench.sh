#!/usr/bin/env bash
# Real-time benchmark of manip_rt's loop against cyclictest, in the same run,
# one after the other, same SCHED_FIFO priority, pinned to the same CPU:
#   1. idle:   bench_rt (60 s paced at 4 kHz), then cyclictest -i 250 (60 s)
#   2. stress: the same under `stress-ng --cpu 2`
# Prints a Markdown table (wake-up latency p50/p99/p99.9, compute p99,
# overruns, logger drops) for docs/controller.md / docs/benchmarks.md.
#
# Usage: bench/run_rt_bench.sh [BUILD_DIR] ; env: SECONDS_PER_RUN (60), CPU (1), PRIO (80)
# Needs root (SCHED_FIFO, mlockall), cyclictest (rt-tests) and stress-ng.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${1:-$here/build}"
secs="${SECONDS_PER_RUN:-60}"
cpu="${CPU:-1}"
prio="${PRIO:-80}"
bench="$build/bench/bench_rt"
[ -x "$bench" ] || { echo "run_rt_bench: $bench not built (ninja -C $build bench_rt)" >&2; exit 2; }
command -v cyclictest >/dev/null || { echo "run_rt_bench: cyclictest missing (apt-get install rt-tests)" >&2; exit 2; }
command -v stress-ng >/dev/null || { echo "run_rt_bench: stress-ng missing" >&2; exit 2; }
[ "$(id -u)" -eq 0 ] || echo "run_rt_bench: warning: not root: SCHED_FIFO/mlockall will fail and the figures mean little" >&2
out="$(mktemp -d)"
trap 'rm -rf "$out"; [ -n "${stress_pid:-}" ] && kill "$stress_pid" 2>/dev/null || true' EXIT

loops=$((secs * 4000))

# Percentile (in us) from a cyclictest histogram (-h): lines "bin count".
hist_pct() {  # file quantile
  awk -v q="$2" '!/^#/ && NF>=2 { b[$1+0]=$2+0; n+=$2 } 
    /^# Histogram Overflows/ { ov=$4+0 }
    END { n+=ov; t=q*n; acc=0; for (i=0;i<100000;i++) if (i in b) { acc+=b[i]; if (acc>=t) { print i+1; exit } } print ">hist" }' "$1"
}
json() { python3 -c "import json,sys; print(json.load(open('$1'))['$2'])"; }

run_pair() {  # label
  local label="$1"
  (cd "$here" && "$bench" --seconds "$secs" --priority "$prio" --cpu "$cpu" >"$out/$label.json" 2>"$out/$label.err") || {
    echo "run_rt_bench: bench_rt failed ($label):" >&2; cat "$out/$label.err" >&2; exit 1; }
  cyclictest -m -q -p "$prio" -i 250 -a "$cpu" -t 1 -l "$loops" -h 2000 >"$out/$label.cyc" 2>&1
  local cyc_max
  cyc_max=$(awk '/^# Max Latencies/ {print $4+0}' "$out/$label.cyc")
  printf '| %s | manip_rt (sim, logger) | %s | %s | %s | %s | %s | %s | %s |\n' "$label" \
    "$(json "$out/$label.json" latency_p50_us)" "$(json "$out/$label.json" latency_p99_us)" \
    "$(json "$out/$label.json" latency_p999_us)" "$(json "$out/$label.json" latency_max_us)" \
    "$(json "$out/$label.json" compute_p99_us)" "$(json "$out/$label.json" overruns)" \
    "$(json "$out/$label.json" logger_drops)"
  printf '| %s | cyclictest -i 250 | %s | %s | %s | %s | - | - | - |\n' "$label" \
    "$(hist_pct "$out/$label.cyc" 0.50)" "$(hist_pct "$out/$label.cyc" 0.99)" "$(hist_pct "$out/$label.cyc" 0.999)" "$cyc_max"
}

echo "# manip_rt real-time benchmark: $(date -u +%Y-%m-%dT%H:%MZ), $(uname -r) ($(uname -v)), $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
echo "# ${secs} s per run, SCHED_FIFO priority $prio, CPU $cpu; latency = wake-up - deadline [us] (1 us bins: upper edge)"
echo
echo "| load | what | lat p50 | lat p99 | lat p99.9 | lat max | compute p99 | overruns | logger drops |"
echo "|---|---|---|---|---|---|---|---|---|"
run_pair idle
stress-ng --cpu 2 --timeout $((secs * 3))s >/dev/null 2>&1 &
stress_pid=$!
sleep 2
run_pair "stress-ng --cpu 2"
kill "$stress_pid" 2>/dev/null || true
wait "$stress_pid" 2>/dev/null || true
stress_pid=""
