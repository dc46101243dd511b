#!/usr/bin/env bash
# Configure and build manip into build/ (Release, warnings as errors).
# Usage: scripts/build.sh [extra cmake args]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DMANIP_WERROR=ON "$@" >/dev/null
ninja -C build
