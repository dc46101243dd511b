#!/usr/bin/env bash
# What each sanitizer check group costs on pem's kind of arithmetic (10 x 10
# fixed-size Eigen products; bench/sanitizer/riccati_kernel.cpp), against the
# same kernel built without instrumentation in the same run. The flag sets are
# the sanitizer pass's (scripts/test.sh: -O1, ASan + UBSan) with and without
# UBSan's alignment and null checks, which CMakeLists.txt leaves out of the
# numerical modules (MANIP_SANITIZE_NUMERIC).
#
#   bench/run_sanitizer_bench.sh [repeats, default 5] [steps, default 200000]
#
# Prints one line per flag set: median seconds over the repeats and the ratio
# to the uninstrumented -O1 build. Needs g++ (and clang++ for its rows, skipped
# if absent). Figures: docs/benchmarks.md, "Test suite".
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
reps=${1:-5}
steps=${2:-200000}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
eigen=$(pkg-config --cflags eigen3 2>/dev/null || echo -I/usr/include/eigen3)

sets=(
  "g++|-O1"
  "g++|-O3"
  "g++|-O1 -fsanitize=address"
  "g++|-O1 -fsanitize=undefined"
  "g++|-O1 -fsanitize=address,undefined"
  "g++|-O1 -fsanitize=address,undefined -fno-sanitize=alignment,null"
  "g++|-O1 -fsanitize=address,undefined -fno-sanitize=alignment"
  "g++|-O1 -fsanitize=address,undefined -fno-sanitize=null"
  "clang++|-O1 -fsanitize=address,undefined"
)
median() { sort -g | awk '{v[NR]=$1} END{print (NR%2)? v[(NR+1)/2] : (v[NR/2]+v[NR/2+1])/2}'; }
ref=""
n=0
printf '%-9s %-62s %10s %8s\n' compiler flags "median s" "ratio"
for s in "${sets[@]}"; do
  cxx=${s%%|*}
  flags=${s#*|}
  command -v "$cxx" >/dev/null || { printf '%-9s %-62s %10s\n' "$cxx" "$flags" "(absent)"; continue; }
  n=$((n + 1))
  bin="$work/kernel$n"
  # shellcheck disable=SC2086
  "$cxx" -std=c++20 -DNDEBUG $flags $eigen "$here/sanitizer/riccati_kernel.cpp" -o "$bin"
  t=$(for _ in $(seq "$reps"); do "$bin" "$steps" | cut -d' ' -f1; done | median)
  [ -z "$ref" ] && ref=$t
  printf '%-9s %-62s %10.3f %8.1f\n' "$cxx" "$flags" "$t" "$(awk -v a="$t" -v b="$ref" 'BEGIN{print a/b}')"
done
echo "# $(date -u +%F) $(uname -m), $(nproc) cores; $(g++ --version | head -1); ${reps} runs x ${steps} steps"
