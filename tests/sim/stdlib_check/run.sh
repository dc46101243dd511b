#!/usr/bin/env bash
# A seeded simulation must give the same log with another C++ standard library
# (docs/simulation.md, "Randomness"). Builds sim_hash.cpp with the sources it
# needs twice, GCC + libstdc++ and Clang + libc++ (Debian: clang, libc++-dev,
# libc++abi-dev), runs both and compares. Needs a configured build/ for the
# generated LCM headers and version.hpp. About 2 minutes on one core.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)"
cd "$root"
out="$(mktemp -d)"
srcs=(src/sim/session_runner.cpp src/sim/truth.cpp src/sim/linear_human.cpp src/sim/min_jerk.cpp src/sim/presets.cpp
      src/control/trigger.cpp src/control/protocol.cpp src/schema/session_description.cpp src/schema/codes.cpp
      src/model/arm.cpp src/common/perturbation.cpp)
inc=(-Iinclude -Ibuild/version -isystem /usr/include/eigen3 -isystem build/generated)
g++ -std=c++20 -O2 "${inc[@]}" tests/sim/stdlib_check/sim_hash.cpp "${srcs[@]}" -o "$out/gcc"
clang++ -std=c++20 -stdlib=libc++ -O2 "${inc[@]}" tests/sim/stdlib_check/sim_hash.cpp "${srcs[@]}" -o "$out/clang"
a="$("$out/gcc")"
b="$("$out/clang")"
echo "GCC + libstdc++: $a"
echo "Clang + libc++:  $b"
rm -rf "$out"
[ "$a" = "$b" ] && echo "identical" || { echo "DIFFERENT"; exit 1; }
