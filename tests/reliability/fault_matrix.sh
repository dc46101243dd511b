#!/usr/bin/env bash
# Fault matrix of manip_rt (issue 9, docs/reliability.md): hostile packets,
# command storms, signals, kill -9, a full disk, a bus that cannot start, a
# second instance on the same log. For each case: the exit code, the reason
# on stderr, the log read back (session first, gapless cycles, STOPPED cycles
# at the end = the safe law reached, fault records and their history), the
# data lost. Prints a markdown table (the one in docs/reliability.md) and
# exits 1 if any case differs from the expectation.
#
#   tests/reliability/fault_matrix.sh MANIP_RT MANIP_FAULT_TOOL CONFIG
#
# Runs itself inside a private network namespace (multicast route on
# loopback; the host's routes are never touched) and a private mount
# namespace (the full-disk case mounts a 2 MiB tmpfs). Needs root (or user
# namespaces): where unshare is not permitted it skips with exit 77.
set -u
RT=$1 TOOL=$2 CFG=$3
if [ -z "${MANIP_FM_INNER:-}" ]; then
  if ! unshare -n -m true 2>/dev/null; then
    echo "SKIP: unshare -n -m not permitted here (needs root or user namespaces): fault matrix not run"
    exit 77
  fi
  exec env MANIP_FM_INNER=1 unshare -n -m --propagation private bash "$0" "$@"
fi
ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo || {
  echo "SKIP: cannot set up the multicast route in the private network namespace"; exit 77; }

URL='udpm://239.255.76.67:7667?ttl=0'
W=$(mktemp -d /tmp/manip_fault_matrix.XXXXXX)
trap 'umount "$W/full" 2>/dev/null; rm -rf "$W"' EXIT
# The matrix tests what hostile input, signals and files do, not the host's
# timing: on a shared CI machine or a VM an overrun fault (3 late cycles in a
# row) would make the exit codes flaky, so the overrun limits are relaxed in a
# copy of the config (latency under a storm is measured separately:
# docs/reliability.md).
sed -e 's/^\(  overrun_fault_consecutive:\) *[0-9]*/\1 100000/' \
    -e 's/^\(  overrun_fault_per_second:\) *[0-9]*/\1 100000/' "$CFG" >"$W/rt.yaml"
grep -q "overrun_fault_consecutive: 100000" "$W/rt.yaml" || { echo "cannot relax the overrun limits in $CFG"; exit 1; }
CFG=$W/rt.yaml
SHUTDOWN=40   # safety.shutdown_cycles in config/rt.yaml: STOPPED cycles at the end of every orderly stop
FAIL=0
ROWS=()

paced() {  # paced session of $1 s in the background; log $W/$2.lcm, stderr $W/$2.err
  "$RT" --backend sim --config "$CFG" --realtime --duration "$1" --out "$W/$2.lcm" >"$W/$2.out" 2>"$W/$2.err" &
  PID=$!
  sleep 0.7   # set-up (config, bus) before the hostile input
}
field() { sed -n "s/.* $1 \([^ ]*\).*/\1/p" <<<" $2"; }
row() {  # name input expected_rc rc extra_check_ok note
  local name=$1 input=$2 want=$3 rc=$4 ok=$5 note=$6 log=$W/$1.lcm chk="" reason
  if [ -f "$log" ]; then chk=$("$TOOL" check "$log"); else chk="no log file"; fi
  reason=$(grep -E "interrupted by|FAULT|LOG WRITE FAILED|cannot|exists|in use|refus|duration|session|error" "$W/$name.err" 2>/dev/null |
           grep -v "^manip_rt [0-9]" | tail -1 | cut -c1-110)
  local status=PASS
  if [ "$rc" != "$want" ] || [ "$ok" != 1 ]; then status=FAIL; FAIL=1; fi
  local logcol
  if [ -f "$log" ]; then
    logcol="states $(field states "$chk"), gaps $(field gaps "$chk"), STOPPED at end $(field stopped_tail "$chk"), faults $(field faults "$chk") (history $(field history "$chk")), skipped $(field skipped_bytes "$chk") B, truncated tail $(field truncated_tail "$chk"), $(( $(field bytes "$chk") / 1024 )) KiB"
  else
    logcol="no log file"
  fi
  ROWS+=("| $name | $input | $rc (want $want) | ${reason//|/\\|} | $logcol | $note | $status |")
  echo "[$status] $name: exit $rc (want $want); $chk; $note" >&2
}
stopped_ok() { [ "$(field stopped_tail "$("$TOOL" check "$W/$1.lcm")")" -ge "$SHUTDOWN" ] && [ "$(field gaps "$("$TOOL" check "$W/$1.lcm")")" = 0 ] && echo 1 || echo 0; }

# 1. malformed commands: string length 0, -1, INT32_MIN, too large
paced 4 malformed
for len in 0 -1 -2147483648 2147483647 1000; do "$TOOL" send "$URL" malformed "$len" >>"$W/malformed.send"; done
wait $PID; rc=$?
row malformed "command_t, sender length 0 / -1 / INT32_MIN / 2^31-1 / 1000" 0 $rc "$(stopped_ok malformed)" \
  "answered: $(awk '{a+=$4; u+=$8} END {print a" of 5, "u" undecodable"}' "$W/malformed.send")"

# 2. garbage flood
paced 2 garbage
"$TOOL" send "$URL" garbage 20000 >"$W/garbage.send"
wait $PID; rc=$?
row garbage "20 000 random packets (1-300 B) on MANIP_COMMAND" 0 $rc "$(stopped_ok garbage)" "$(cat "$W/garbage.send")"

# 3. command flood
paced 3 flood
"$TOOL" send "$URL" flood 100000 >"$W/flood.send"
wait $PID; rc=$?
sum=$(grep -o "commands received on the bus [0-9]*, accepted [0-9]*, rejected [0-9]*\(; [0-9]* LCM packets dropped by the kernel\)\?" "$W/flood.err")
row flood "100 000 valid commands, unpaced" 0 $rc "$(stopped_ok flood)" "$(cat "$W/flood.send"); summary: ${sum:-none}"

# 4. ESTOP/FAULT_RESET storm (ends with a reset: nothing latched at the end)
paced 3 storm
"$TOOL" send "$URL" storm 30000 >"$W/storm.send"
wait $PID; rc=$?
chk=$("$TOOL" check "$W/storm.lcm")
hist_ok=$([ "$(field history "$chk")" -le "$(field states "$chk")" ] && echo 1 || echo 0)
ok=$([ "$(stopped_ok storm)" = 1 ] && [ "$hist_ok" = 1 ] && echo 1 || echo 0)
lines=$(grep -c "FAULT at cycle" "$W/storm.err")
# exit 0 if the last FAULT_RESET was handled, 7 if an ESTOP stayed latched (both orderly)
want=0; [ "$rc" = 7 ] && want=7
row storm "30 000 ESTOP/FAULT_RESET pairs" $want $rc "$ok" \
  "$(cat "$W/storm.send"); $lines FAULT lines on stderr; history states <= states: $hist_ok"

# 5. a fault latched to the end of a paced --duration run
paced 2 latched
"$TOOL" send "$URL" estop 1 >/dev/null
wait $PID; rc=$?
row latched "one ESTOP, never reset; run ends by --duration" 7 $rc "$(stopped_ok latched)" "a faulted session must not exit 0"

# 6-8. signals
for sig in HUP TERM INT; do
  paced 3 "sig$sig"
  kill -s "$sig" $PID
  wait $PID; rc=$?
  row "sig$sig" "SIG$sig during the session" 130 $rc "$(stopped_ok "sig$sig")" "orderly stop"
done

# 9. SIGPIPE: stderr into a pipe whose reader quits after one line
( "$RT" --backend sim --config "$CFG" --realtime --duration 2 --out "$W/sigpipe.lcm" 2>&1 | head -1 >/dev/null
  echo "${PIPESTATUS[0]}" >"$W/sigpipe.rc" )
: >"$W/sigpipe.err"
rc=$(cat "$W/sigpipe.rc")
chk=$("$TOOL" check "$W/sigpipe.lcm")
ok=$([ "$(stopped_ok sigpipe)" = 1 ] && [ "$(field states "$chk")" -ge 8000 ] && echo 1 || echo 0)
row sigpipe "\`manip_rt ... 2>&1 \| head -1\`" 0 "$rc" "$ok" "session ran to its end (2 s = 8000 cycles + stop)"

# 10. kill -9, as fast as possible
"$RT" --backend sim --config "$CFG" --afap --lcm-url none --out "$W/kill9.lcm" >/dev/null 2>"$W/kill9.err" &
PID=$!
# Kill once the log holds 16 MiB (mid-session on any machine: the whole
# as-fast-as-possible session is ~430 MB), not after a fixed time: a fast CI
# machine finished the whole session within 1.5 s.
for _ in $(seq 1 3000); do
  [ "$(stat -c %s "$W/kill9.lcm" 2>/dev/null || echo 0)" -ge 16777216 ] && break
  kill -0 $PID 2>/dev/null || break
  sleep 0.01
done
kill -9 $PID 2>/dev/null; wait $PID; rc=$?
chk=$("$TOOL" check "$W/kill9.lcm")
ok=$([ "$(field gaps "$chk")" = 0 ] && [ "$(field states "$chk")" -gt 0 ] && echo 1 || echo 0)
row kill9 "kill -9 mid-session (log at 16 MiB), as fast as possible" 137 $rc "$ok" \
  "no safe stop possible (SIGKILL); log readable and gapless up to cycle $(field cycles "$chk" | sed 's/.*\.\.//')"

# 11. disk full: a 2 MiB tmpfs
mkdir -p "$W/full" && mount -t tmpfs -o size=2m tmpfs "$W/full"
"$RT" --backend sim --config "$CFG" --afap --lcm-url none --out "$W/full/diskfull.lcm" >/dev/null 2>"$W/diskfull.err"
rc=$?
cp "$W/full/diskfull.lcm" "$W/diskfull.lcm" 2>/dev/null
chk=$("$TOOL" check "$W/diskfull.lcm")
claimed=$(sed -n 's/.* \([0-9]*\) events in the file.*/\1/p' "$W/diskfull.err" | tail -1)
ok=$([ -n "$claimed" ] && [ "$claimed" -le "$(field events "$chk")" ] && [ "$(field gaps "$chk")" = 0 ] && echo 1 || echo 0)
row diskfull "log on a full 2 MiB tmpfs" 6 $rc "$ok" "summary claims ${claimed:-?} events in the file, $(field events "$chk") readable"
umount "$W/full"

# 12. bus start failure: no stub log
"$RT" --backend sim --config "$CFG" --realtime --duration 1 --lcm-url 'nosuch://x' --out "$W/busfail.lcm" >/dev/null 2>"$W/busfail.err"
rc=$?
row busfail "--lcm-url nosuch://x (LCM cannot start)" 10 $rc "$([ ! -e "$W/busfail.lcm" ] && echo 1 || echo 0)" \
  "stub log left behind: $([ -e "$W/busfail.lcm" ] && echo "yes, $(stat -c %s "$W/busfail.lcm") B" || echo no)"

# 13. a second instance on the same log with --force
paced 3 second
"$RT" --backend sim --config "$CFG" --realtime --duration 1 --force --lcm-url none --out "$W/second.lcm" >/dev/null 2>"$W/second2.err"
rc2=$?
wait $PID; rc=$?
cat "$W/second2.err" >>"$W/second.err"
ok=$([ "$rc" = 0 ] && [ "$(stopped_ok second)" = 1 ] && echo 1 || echo 0)
row second "second manip_rt --force on the same --out" 6 $rc2 "$ok" "first instance: exit $rc, its log intact"

# 14. bad --duration
for d in nan -1 inf; do
  "$RT" --backend sim --config "$CFG" --duration "$d" --lcm-url none --out "$W/dur.lcm" >/dev/null 2>"$W/dur$d.err"
  rc=$?
  named=$(grep -c -- "--duration" "$W/dur$d.err")
  cp "$W/dur$d.err" "$W/dur_$d.err"
  row "dur_$d" "--duration $d" 2 $rc "$([ "$named" -ge 1 ] && [ ! -e "$W/dur.lcm" ] && echo 1 || echo 0)" "message names the option: $([ "$named" -ge 1 ] && echo yes || echo no)"
  rm -f "$W/dur.lcm"
done

echo
echo "| case | input | exit | reason (stderr) | log read back | data / answers | result |"
echo "|---|---|---|---|---|---|---|"
printf '%s\n' "${ROWS[@]}"
exit $FAIL
