#!/bin/sh
# A simulated log read through manip-lcmtypes.jar (ReadLog.java, as MATLAB
# would through the same classes) must give the values the C++ reader
# (log_summary) reports: session sample rate, schema version, number of
# states, perturbation-phase states, onsets, and the code constants.
# Usage: java_read_log.sh MANIP_SIM LOG_SUMMARY JAR LCM_JAR JAVAC JAVA SRC_DIR
set -eu
sim=$1 summary=$2 jar=$3 lcmjar=$4 javac=$5 java=$6 src=$7
work=$(mktemp -d /tmp/manip_java_XXXXXX)
trap 'rm -rf "$work"' EXIT
"$sim" --out "$work/s.lcm" --movements 10 --reps 1 --seed 7 -q
"$summary" "$work/s.lcm" > "$work/cpp.txt"
"$javac" -cp "$jar:$lcmjar" -d "$work" "$src/ReadLog.java"
"$java" -cp "$work:$jar:$lcmjar" ReadLog "$work/s.lcm" > "$work/java.txt"
cat "$work/java.txt"
# The check must be able to fail: a log with states and perturbed trials.
grep -q '^states [1-9]' "$work/cpp.txt" && grep -q '^perturbation_states [1-9]' "$work/cpp.txt" && grep -q '^onsets 8$' "$work/cpp.txt" || { echo "FAIL: unexpected C++ summary"; cat "$work/cpp.txt"; exit 1; }
if diff -u "$work/cpp.txt" "$work/java.txt"; then echo "java: jar reader agrees with the C++ reader"; else echo "FAIL: Java (+) and C++ (-) readers differ"; exit 1; fi
