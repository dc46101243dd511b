#!/usr/bin/env bash
# Real-time benchmark of manip_rt's loop against cyclictest in the same run,
# same SCHED_FIFO priority, pinned to the same CPU, one after the other:
#   idle, then under `stress-ng --cpu 2`.
# The host's load drifts (shared VM), so each condition is measured in ROUNDS
# interleaved rounds (manip_rt, cyclictest, manip_rt, ...) of SECONDS_PER_RUN /
# ROUNDS each, and the latency histograms of the rounds are merged per tool.
# manip_rt = bench_rt: the full stack (sim backend, controller, logger thread
# writing the LCM log) paced at 4 kHz; cyclictest -i 250 = the same period.
# Prints a Markdown table: wake-up latency p50/p99/p99.9/max (us), compute
# p99 (worst round), overruns and logger drops (summed).
#
# Usage: bench/run_rt_bench.sh [BUILD_DIR]
#   env: SECONDS_PER_RUN (60, per tool and condition), ROUNDS (6), CPU (1), PRIO (80)
# Needs root (SCHED_FIFO, mlockall), cyclictest (rt-tests) and stress-ng.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${1:-$here/build}"
secs="${SECONDS_PER_RUN:-60}"
rounds="${ROUNDS:-6}"
cpu="${CPU:-1}"
prio="${PRIO:-80}"
bench="$build/bench/bench_rt"
[ -x "$bench" ] || { echo "run_rt_bench: $bench not built (ninja -C $build bench_rt)" >&2; exit 2; }
command -v cyclictest >/dev/null || { echo "run_rt_bench: cyclictest missing (apt-get install rt-tests)" >&2; exit 2; }
command -v stress-ng >/dev/null || { echo "run_rt_bench: stress-ng missing" >&2; exit 2; }
[ "$(id -u)" -eq 0 ] || echo "run_rt_bench: warning: not root: SCHED_FIFO/mlockall will fail and the figures mean little" >&2
out="$(mktemp -d)"
stress_pid=""
trap 'rm -rf "$out"; [ -n "$stress_pid" ] && kill "$stress_pid" 2>/dev/null || true' EXIT

per=$(( (secs + rounds - 1) / rounds ))
loops=$((per * 4000))

# Percentile [us] (upper bin edge) of merged histograms ("bin count" lines, "# Histogram Overflows: n").
hist_pct() {  # quantile files...
  local q="$1"; shift
  awk -v q="$q" '!/^#/ && NF>=2 { b[$1+0]+=$2+0; n+=$2 }
    /^# Histogram Overflows/ { ov+=$4+0 }
    END { n+=ov; t=q*n; acc=0; for (i=0;i<100000;i++) if (i in b) { acc+=b[i]; if (acc>=t) { print i+1; exit } } print ">range" }' "$@"
}
jsum() { python3 -c "import json,sys; print(sum(json.load(open(f))['$1'] for f in sys.argv[1:]))" "${@:2}"; }
jmax() { python3 -c "import json,sys; print(max(json.load(open(f))['$1'] for f in sys.argv[1:]))" "${@:2}"; }

run_condition() {  # label
  local label="$1" r
  for r in $(seq 1 "$rounds"); do
    (cd "$here" && "$bench" --seconds "$per" --priority "$prio" --cpu "$cpu" --histogram "$out/$label.m.$r.hist" \
      >"$out/$label.m.$r.json" 2>"$out/$label.m.$r.err") || {
      echo "run_rt_bench: bench_rt failed ($label, round $r):" >&2; cat "$out/$label.m.$r.err" >&2; exit 1; }
    cyclictest -m -q -p "$prio" -i 250 -a "$cpu" -t 1 -l "$loops" -h 5000 >"$out/$label.c.$r.cyc" 2>&1
  done
  local cyc_max
  cyc_max=$(awk '/^# Max Latencies/ { if ($4+0 > m) m = $4+0 } END { print m+0 }' "$out/$label".c.*.cyc)
  printf '| %s | manip_rt (sim, logger) | %s | %s | %s | %s | %s | %s | %s |\n' "$label" \
    "$(hist_pct 0.50 "$out/$label".m.*.hist)" "$(hist_pct 0.99 "$out/$label".m.*.hist)" \
    "$(hist_pct 0.999 "$out/$label".m.*.hist)" "$(jmax latency_max_us "$out/$label".m.*.json)" \
    "$(jmax compute_p99_us "$out/$label".m.*.json)" "$(jsum overruns "$out/$label".m.*.json)" \
    "$(jsum logger_drops "$out/$label".m.*.json)"
  printf '| %s | cyclictest -i 250 | %s | %s | %s | %s | - | - | - |\n' "$label" \
    "$(hist_pct 0.50 "$out/$label".c.*.cyc)" "$(hist_pct 0.99 "$out/$label".c.*.cyc)" \
    "$(hist_pct 0.999 "$out/$label".c.*.cyc)" "$cyc_max"
}

echo "# manip_rt real-time benchmark: $(date -u +%Y-%m-%dT%H:%MZ), kernel $(uname -r) ($(uname -v)), $(nproc) CPUs, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
echo "# per tool and condition: ${rounds} interleaved rounds x ${per} s; SCHED_FIFO priority $prio, CPU $cpu"
echo "# latency = wake-up - deadline [us], 1 us bins (upper edge); compute p99 = worst round; overruns, drops = sum"
echo
echo "| load | what | lat p50 | lat p99 | lat p99.9 | lat max | compute p99 | overruns | logger drops |"
echo "|---|---|---|---|---|---|---|---|---|"
run_condition idle
stress-ng --cpu 2 --timeout $((secs * 3 + 60))s >/dev/null 2>&1 &
stress_pid=$!
sleep 2
run_condition "stress-ng --cpu 2"
kill "$stress_pid" 2>/dev/null || true
wait "$stress_pid" 2>/dev/null || true
stress_pid=""
