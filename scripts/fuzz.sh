#!/usr/bin/env bash
# Builds the libFuzzer harnesses of fuzz/ with clang (a separate build in
# build-fuzz/, the normal GCC build is untouched) and runs each for a bounded
# time. Fails (exit 1) if any harness finds a crash, sanitizer report, leak,
# timeout or out-of-memory; the reproducer is left in build-fuzz/artifacts/.
#
#   scripts/fuzz.sh [seconds per harness, default 60] [harness ...]
#
# Harnesses are fuzz/fuzz_<name>.cpp (all of them unless named); seeds are
# read from fuzz/corpus/<name>/ (never written: the growing corpus lives in
# build-fuzz/corpus/<name>/). Prints executions and coverage per harness.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
secs=${1:-60}
shift || true
build=${MANIP_FUZZ_BUILD:-$root/build-fuzz}
jobs=${MANIP_FUZZ_JOBS:-$(nproc)}

launcher=()
if command -v ccache >/dev/null; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
# A unity build (CMake's CMAKE_UNITY_BUILD, as the sanitizer build of
# scripts/test.sh): the harnesses' union of sources in batches of 8, compile
# CPU 597 -> 391 s, wall 302 -> 196 s on the 2-core machine (2026-12-04);
# MANIP_UNITY_BUILD=OFF compiles one file at a time.
mkdir -p "$build"
cmake -S "$root/fuzz" -B "$build" -G Ninja -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_UNITY_BUILD="${MANIP_UNITY_BUILD:-ON}" "${launcher[@]}" >"$build/cmake.log" 2>&1 || { cat "$build/cmake.log"; exit 1; }
ninja -C "$build" -j"$jobs"

names=("$@")
if [ ${#names[@]} -eq 0 ]; then
  for f in "$root"/fuzz/fuzz_*.cpp; do n=$(basename "$f" .cpp); names+=("${n#fuzz_}"); done
fi

# Each harness is one single-threaded process: they run $jobs at a time
# (MANIP_FUZZ_JOBS, default the machine's cores; also the build's jobs), each for its own
# ${secs} s, so the whole run takes about (harnesses / jobs) x secs.
run_one() {
  local n=$1 bin="$build/fuzz_$1" work="$build/corpus/$1" art="$build/artifacts/$1/"
  local log="$build/fuzz_$1.log" seeds=() rc
  mkdir -p "$work" "$art"
  [ -d "$root/fuzz/corpus/$n" ] && seeds=("$root/fuzz/corpus/$n")
  set +e
  # RSS limit: libFuzzer's default 2 GB (OSS-Fuzz: 2.5 GB). ASan's 256 MB
  # quarantine of freed blocks grows a YAML harness's RSS past 500 MB in
  # under a minute without any leak (fuzz_rt_config: 729 MB after 140 000
  # runs; 84 MB with the quarantine off, 2026-12-05), so the former 512 MB
  # failed 60 s runs. One allocation of 512 MB or more is still a finding.
  "$bin" -max_total_time="$secs" -rss_limit_mb=2048 -malloc_limit_mb=512 -timeout=10 -print_final_stats=1 \
    -artifact_prefix="$art" "$work" "${seeds[@]}" >"$log" 2>&1
  rc=$?
  set -e
  echo "$rc" >"$build/fuzz_$n.rc"
}

for n in "${names[@]}"; do
  [ -x "$build/fuzz_$n" ] || { echo "fuzz.sh: no harness fuzz_$n" >&2; exit 1; }
  rm -f "$build/fuzz_$n.rc"
done
running=0
for n in "${names[@]}"; do
  if [ "$running" -ge "$jobs" ]; then wait -n || true; running=$((running - 1)); fi
  echo "== fuzz_$n: ${secs}s (log: $build/fuzz_$n.log)"
  run_one "$n" &
  running=$((running + 1))
done
wait

status=0
summary=()
for n in "${names[@]}"; do
  log="$build/fuzz_$n.log"
  rc=$(cat "$build/fuzz_$n.rc" 2>/dev/null || echo "?")
  execs=$(grep -oE 'stat::number_of_executed_units: *[0-9]+' "$log" | grep -o '[0-9]*$' | tail -1)
  rate=$(grep -oE 'stat::average_exec_per_sec: *[0-9]+' "$log" | grep -o '[0-9]*$' | tail -1)
  last=$(grep -E '^#[0-9]+' "$log" | tail -1)
  cov=$(echo "$last" | grep -o 'cov: [0-9]*' | grep -o '[0-9]*')
  ft=$(echo "$last" | grep -o 'ft: [0-9]*' | grep -o '[0-9]*')
  corp=$(echo "$last" | grep -o 'corp: [0-9]*/[0-9]*[a-zA-Z]*' | cut -d' ' -f2)
  if [ "$rc" = "0" ]; then result=ok; else
    result="FAILED (exit $rc)"
    status=1
    echo "== fuzz_$n (log: $log)" >&2
    grep -E 'ERROR|SUMMARY|invariant broken|Test unit written|deadly signal|Timeout|out-of-memory|leak' "$log" | head -20 >&2 || true
  fi
  summary+=("fuzz_$n: ${execs:-?} executions (${rate:-?}/s), coverage ${cov:-?} edges, ${ft:-?} features, corpus ${corp:-?}: $result")
done
echo "== summary (${secs}s per harness)"
printf '%s\n' "${summary[@]}"
exit $status
