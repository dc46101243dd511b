#!/bin/sh
# The .deb as a lab would install it (docs/install.md): build the installed
# targets in the existing build tree, `cpack -G DEB`, check the declared
# Debian dependencies, extract with `dpkg -x` into a clean prefix and run the
# installed tools from another directory with a clean environment:
#   manip_sim --human neuromech finds arm_model.yaml through the search path
#   (<prefix>/share/manip/config; not the source tree), estimate_impedance
#   estimates the session, manip_rt finds rt.yaml the same way and records a
#   session, Debian's python3 imports manipplot and the generated types from
#   <prefix>/lib/python3/dist-packages. The package carries a machine-readable
#   /usr/share/doc/manip/copyright (Debian policy 12.5), changelog.Debian.gz
#   for its version, a manual page per program when the build tree generates
#   them (help2man; required when help2man is installed), the jar under its
#   Debian Java name; lintian, when installed, is run and its findings
#   printed: an error (E:) fails the test, warnings and info do not.
# Usage: deb_install.sh BUILD_DIR
set -eu
build=$(cd "$1" && pwd)
work=$(mktemp -d /tmp/manip_deb_XXXXXX)
trap 'rm -rf "$work"' EXIT
t0=$(date +%s)

# manip_installable: every program, the generated types, the jar and the manual pages (when built).
targets="manip_installable"
man=no
if grep -q '^MANIP_MAN_PAGES:INTERNAL=ON' "$build/CMakeCache.txt"; then
  man=yes
elif command -v help2man > /dev/null 2>&1 && ! grep -q '^MANIP_MAN:STRING=OFF' "$build/CMakeCache.txt" \
     && ! grep -q '^MANIP_SANITIZE:BOOL=ON' "$build/CMakeCache.txt"; then
  echo "FAIL: help2man is installed but $build generates no manual pages (reconfigure: cmake $build)"; exit 1
fi
cmake --build "$build" --target $targets -- -j2 > "$work/build.log" 2>&1 || { tail -30 "$work/build.log"; exit 1; }
(cd "$work" && cpack -G DEB --config "$build/CPackConfig.cmake" -B "$work/pkg" > "$work/cpack.log" 2>&1) \
  || { tail -30 "$work/cpack.log"; exit 1; }
deb=$(ls "$work"/pkg/manip_*.deb)
echo "package: $(basename "$deb") ($(du -k "$deb" | cut -f1) KiB, built in $(( $(date +%s) - t0 )) s)"

depends=$(dpkg-deb -f "$deb" Depends)
echo "Depends: $depends"
for d in liblcm1 libyaml-cpp0.7 libstdc++6 libc6 python3-matplotlib python3-numpy; do
  echo "$depends" | grep -q "$d" || { echo "FAIL: Depends lacks $d"; exit 1; }
done

root="$work/root"
dpkg -x "$deb" "$root"
for f in usr/bin/manip_sim usr/bin/estimate_impedance usr/bin/manip_rt usr/share/manip/config/rt.yaml \
         usr/share/manip/config/arm_model.yaml usr/share/manip/lcmtypes/state_t.lcm \
         usr/lib/python3/dist-packages/manipplot/__init__.py usr/lib/python3/dist-packages/manip/state_t.py \
         usr/share/doc/manip/exit-codes.md usr/share/doc/manip/copyright; do
  [ -e "$root/$f" ] || { echo "FAIL: package lacks /$f"; exit 1; }
done
# copyright-format 1.0: the Format line, a Files paragraph with Copyright and License.
cr="$root/usr/share/doc/manip/copyright"
for field in '^Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/' '^Upstream-Name: manip' \
             '^Files: \*' '^Copyright: ' '^License: '; do
  grep -q "$field" "$cr" || { echo "FAIL: /usr/share/doc/manip/copyright lacks '$field'"; exit 1; }
done
echo "copyright: $(grep '^License: ' "$cr" | head -1)"
# Debian policy 12.7: changelog.Debian.gz, its latest entry for this package version, by the Maintainer.
version=$(dpkg-deb -f "$deb" Version) maintainer=$(dpkg-deb -f "$deb" Maintainer)
cl="$root/usr/share/doc/manip/changelog.Debian.gz"
[ -e "$cl" ] || { echo "FAIL: package lacks /usr/share/doc/manip/changelog.Debian.gz"; exit 1; }
zcat "$cl" | head -1 | grep -q "^manip ($version) " || { echo "FAIL: changelog.Debian.gz is not for $version:"; zcat "$cl"; exit 1; }
zcat "$cl" | grep -q "^ -- $maintainer  " || { echo "FAIL: changelog.Debian.gz not signed by the Maintainer ($maintainer)"; zcat "$cl"; exit 1; }
echo "changelog: $(zcat "$cl" | head -1); Maintainer: $maintainer"
# One manual page per program, built from its --help (help2man), that man renders without a warning.
if [ "$man" = yes ]; then
  n=0
  for b in "$root"/usr/bin/*; do
    p="$root/usr/share/man/man1/$(basename "$b").1.gz"
    [ -e "$p" ] || { echo "FAIL: no manual page for /usr/bin/$(basename "$b")"; exit 1; }
    zcat "$p" | grep -q '^\.SH "\?EXIT' || zcat "$p" | grep -qi 'exit codes' \
      || { echo "FAIL: $(basename "$p") has no exit-code table"; exit 1; }
    if zcat "$p" | grep -q 'manual page for'; then echo "FAIL: $(basename "$p"): NAME has no description"; exit 1; fi
    if command -v man > /dev/null 2>&1; then
      # As lintian renders it (Check/Documentation/Manual.pm: 120 columns, -Tutf8 -Z).
      w=$(LC_ALL=C.UTF-8 MANWIDTH=120 man --warnings -E UTF-8 -l -Tutf8 -Z "$p" 2>&1 > /dev/null) || true
      [ -z "$w" ] || { echo "FAIL: man warns on $(basename "$p"): $w"; exit 1; }
    fi
    n=$((n + 1))
  done
  echo "man pages: $n ($(zcat "$root/usr/share/man/man1/manip_sim.1.gz" | grep -A1 '^\.SH NAME' | tail -1))"
else
  echo "man pages: not generated (MANIP_MAN=OFF, or no help2man when configured; apt-get install help2man)"
fi
if command -v lintian > /dev/null 2>&1; then
  # -I: info tags too (printed, never failing); an error fails the test.
  rc=0
  lintian -I --tag-display-limit 0 "$deb" > "$work/lintian.txt" 2>&1 || rc=$?
  e=$(grep -c '^E: ' "$work/lintian.txt") w=$(grep -c '^W: ' "$work/lintian.txt") i=$(grep -c '^I: ' "$work/lintian.txt")
  echo "lintian ($(lintian --version)): $e errors, $w warnings, $i info"
  sed 's/^/  /' "$work/lintian.txt"
  [ "$e" -eq 0 ] || { echo "FAIL: lintian reports errors"; exit 1; }
  # Exit 1 is lintian's "errors found"; anything above is lintian itself failing.
  [ "$rc" -le 1 ] || { echo "FAIL: lintian exited $rc"; exit 1; }
else
  echo "lintian: not installed (optional: apt-get install lintian)"
fi
if grep -q '^MANIP_JAVA:BOOL=ON' "$build/CMakeCache.txt"; then
  # Debian Java policy: manip-lcmtypes-<version>.jar, and manip-lcmtypes.jar a link to it.
  jar="$root/usr/share/java/manip-lcmtypes.jar"
  [ -L "$jar" ] && [ "$(readlink "$jar")" = "manip-lcmtypes-${version%-*}.jar" ] && [ -f "$jar" ] \
    || { echo "FAIL: /usr/share/java/manip-lcmtypes.jar is not a link to manip-lcmtypes-${version%-*}.jar"; ls -l "$root/usr/share/java"; exit 1; }
  echo "jar: /usr/share/java/manip-lcmtypes.jar -> $(readlink "$jar")"
fi

# Another directory, nothing of the build or source tree in the environment.
mkdir -p "$work/elsewhere" "$work/home"
cd "$work/elsewhere"
run() { env -i PATH="$root/usr/bin:/usr/bin:/bin" HOME="$work/home" LANG=C.UTF-8 "$@"; }
run manip_sim --version
run manip_sim --human neuromech --movements 12 --reps 1 --seed 3 --out session.lcm
[ -s session.lcm ] || { echo "FAIL: no session written"; exit 1; }
run estimate_impedance session.lcm --json est.json > est.txt 2> est.err || rc=$?
rc=${rc:-0}
# 0 or 1 (a short session may exclude a trial): estimated; anything else is a failure.
[ "$rc" -le 1 ] || { echo "FAIL: estimate_impedance exit $rc"; cat est.err; exit 1; }
[ -s est.json ] || { echo "FAIL: no estimate written"; exit 1; }
head -5 est.txt
# manip_rt: rt.yaml from the package's share/manip/config, found from here (no config/ in this directory).
run manip_rt --version
run manip_rt --movements 2 --lcm-url none --out rt.lcm 2> rt.err || { echo "FAIL: manip_rt exit $?"; cat rt.err; exit 1; }
grep -q "config $root/usr/share/manip/config/rt.yaml" rt.err || { echo "FAIL: manip_rt did not use the packaged rt.yaml"; cat rt.err; exit 1; }
[ -s rt.lcm ] || { echo "FAIL: manip_rt wrote no log"; exit 1; }
rc=0
run estimate_impedance rt.lcm -q > rt_est.txt 2>&1 || rc=$?
grep -q "session sim-session-001" rt_est.txt || { echo "FAIL: estimate_impedance on manip_rt's log (exit $rc)"; cat rt_est.txt; exit 1; }
echo "manip_rt: $(head -1 rt.err | cut -c1-160)"
run /usr/bin/python3 -c "
import sys
sys.path.insert(0, '$root/usr/lib/python3/dist-packages')
import manipplot, manipplot.io, manipplot.tables
from manip import state_t, session_t
assert manipplot.__file__.startswith('$root'), manipplot.__file__
assert state_t.PHASE_PERTURBATION == 3
print('python3: manipplot', manipplot.__version__, 'from', manipplot.__file__)
"
echo "install test: ok in $(( $(date +%s) - t0 )) s"
