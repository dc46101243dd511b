#!/usr/bin/env bash
# README command 2 (and CI): set-up, build with warnings as errors, run all
# tests; then the same tests built with AddressSanitizer + UBSan.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
jobs=$(nproc)
scripts/setup.sh
echo "== build (Release, -Werror) ==" >&2
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DMANIP_WERROR=ON >/dev/null
ninja -C build
echo "== tests ==" >&2
(cd build && ctest --output-on-failure -j "$jobs")
# Fuzzing with libFuzzer (clang, ASan + UBSan): every harness of fuzz/ for a
# bounded time; a crash, leak, timeout or out-of-memory fails the run.
if [ "${MANIP_SKIP_FUZZ:-0}" != "1" ]; then
  echo "== fuzzing (${MANIP_FUZZ_SECONDS:-15} s per harness) ==" >&2
  scripts/fuzz.sh "${MANIP_FUZZ_SECONDS:-15}"
fi
if [ "${MANIP_SKIP_SANITIZERS:-0}" != "1" ]; then
  echo "== build (ASan + UBSan) ==" >&2
  cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DMANIP_WERROR=ON -DMANIP_SANITIZE=ON \
    -DMANIP_BENCH=OFF >/dev/null
  ninja -C build-asan
  echo "== tests under sanitizers ==" >&2
  # The manipulandum diagnosis sessions run ~100-130 pem fits each: ~8 s of
  # CPU in Release, ~3.5 min each under ASan (2026-11-26, after the pem
  # speed-up). The 100-movement sessions run in the Release pass only; the
  # 50-movement likelihood-check case (3.5 min here) runs under the
  # sanitizers too, so the likelihood check's threads, folds and every
  # correction path are covered; so do the single-joint diagnoses and every
  # unit test of the diagnosis.
  asan_skip="diagnosis:(manipulandum: (a clean session|hidden)|planar sensor: hidden)"
  (cd build-asan && ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    ctest --output-on-failure -j "$jobs" -LE no_sanitize -E "$asan_skip")
fi
