#!/usr/bin/env bash
# Idempotent set-up of every dependency of manip on Debian 12.
# Debian packages via apt-get; the one exception is PyPI `lcm` (pinned) in a
# project-local virtualenv (.venv), used by Python interoperability tests and the
# Python reference benchmark, because Debian ships no Python LCM.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

PKGS=(
  build-essential cmake ninja-build pkg-config
  libeigen3-dev liblcm-dev liblcm-bin
  catch2 libyaml-cpp-dev libcli11-dev nlohmann-json3-dev
  libreaderwriterqueue-dev
  python3 python3-venv python3-numpy python3-scipy python3-matplotlib
  rt-tests stress-ng iproute2
  chromium fonts-dejavu-core
  libmatio-dev
  python3-pygame xvfb xauth
  # install/CPack (.deb dependencies by dpkg-shlibdeps) and the Java/MATLAB jar (docs/matlab.md)
  dpkg-dev file default-jdk-headless liblcm-java
  # the .deb's manual pages (help2man, from each program's --help) and its check (lintian, run
  # by ctest install:deb; about 150 small Perl packages, 14 MiB, under 1 % of this list's download)
  help2man lintian
  qemu-system-x86 busybox-static cpio xz-utils
  # libFuzzer harnesses (scripts/fuzz.sh) and the second standard library check
  clang libfuzzer-14-dev libclang-rt-14-dev libc++-dev libc++abi-dev
)

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
  echo "setup: installing ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# Python side: Debian's python3 (for python3-scipy) plus pinned PyPI lcm.
LCM_PY_VERSION=1.5.3
venv="$here/.venv"
if [ ! -x "$venv/bin/python" ]; then
  /usr/bin/python3 -m venv --system-site-packages "$venv"
fi
if ! "$venv/bin/python" -c "import lcm, sys; sys.exit(0 if getattr(lcm,'__version__','$LCM_PY_VERSION')=='$LCM_PY_VERSION' else 1)" 2>/dev/null; then
  "$venv/bin/python" -m pip install -q --disable-pip-version-check "lcm==$LCM_PY_VERSION"
fi
echo "setup: ok" >&2
