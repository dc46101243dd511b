#!/bin/sh
# The CANopen stack on a real kernel CAN stack: boots a Debian kernel with the
# vcan modules under qemu (software emulation; this machine's kernel has no
# AF_CAN), creates vcan0 + vcan1 through rtnetlink, runs two manip_fake_drive
# processes (simulated CiA 402 drives, one per bus, as in config/can.yaml) and
# manip_vcan_session (the master, tests/canopen/qemu/vcan_session.cpp): SDO
# start-up, enable, 10 s of 2 kHz cyclic exchange (SYNC from the 4 kHz loop),
# frame counts vs the configured rates from a sniffer socket, zero unexpected
# frames, SYNC period statistics, disable; then prints the figures.
# Then, across processes, the commissioning tool against the same drive
# processes: manip_can_check on the good set-up must exit 0; on a set-up with
# a missing node (configured on vcan2, where no drive runs) it must exit 8
# with "never booted", and with a wrong node id (3 configured, 2 answering on
# vcan1) exit 8 with "unexpected node id".
#
# Timing inside TCG is not meaningful for latency: the test checks the
# protocol (every SYNC on the wire answered by RPDO1, TPDO1 and TPDO2 within
# +-2 at the window edges, every SYNC the master counted seen on the wire,
# zero unexpected frames, no EMCY, no fault, drives disabled at the end).
# Timing gates are relative to what the emulated loop achieved, never to the
# host's speed: the median SYNC period at least 450 us and at most
# max(750 us, 500 us + 2 x the loop's median cycle), and at least 30 % of
# min(SYNC periods in the window, loop cycles run). The emulated loop reached
# 0.9 to 1.5 kHz of 4 kHz on an idle shared 2-core host (26-43 % of the
# configured SYNCs) and 656 Hz on a loaded CI host (median SYNC period 873 us,
# which failed the former fixed 750 us gate); the master can only send at a
# loop cycle, and a due SYNC goes out at the first one past its due time, so
# an exactly-working master sends at least half the achievable count (0.57 and
# 0.94 measured). The gates catch a stalled or early master on any host; the
# achieved figures are printed. The period spread and the SYNC -> TPDO round
# trip are reported, not gated. Three vCPUs under multi-threaded TCG (master + two
# drive processes), each drive's SYNC-loss alarm off (see the init script).
#
# Idempotent: downloads (apt-get download) and extracts the kernel once into
# the cache directory ($MANIP_QEMU_CACHE, default <build>/qemu-cache).
# Usage: scripts/qemu_vcan_test.sh [build-dir]
# Exit: 0 pass, 1 fail, 77 skipped (qemu, busybox or the kernel package unavailable).
set -eu
here=$(cd "$(dirname "$0")/.." && pwd)
build=$(cd "${1:-$here/build}" && pwd)
cache=${MANIP_QEMU_CACHE:-$build/qemu-cache}
duration=${MANIP_VCAN_DURATION:-10}
skip() { echo "qemu vcan test: SKIPPED: $*"; exit 77; }

command -v qemu-system-x86_64 >/dev/null || skip "qemu-system-x86_64 not installed (scripts/setup.sh)"
bb=$(command -v busybox || true)
[ -n "$bb" ] || skip "busybox not installed (busybox-static)"
if ldd "$bb" >/dev/null 2>&1; then skip "$bb is not static (install busybox-static)"; fi
for app in apps/manip_fake_drive apps/manip_can_check apps/manip_rt tests/canopen/qemu/manip_vcan_session; do
  [ -x "$build/$app" ] || { echo "qemu vcan test: FAIL: $build/$app not built (ninja manip_fake_drive manip_can_check manip_rt manip_vcan_session)"; exit 1; }
done
mkdir -p "$cache"

# --- kernel + the four CAN modules (once) ---------------------------------
if [ ! -s "$cache/vmlinuz" ] || [ ! -s "$cache/vcan.ko" ]; then
  deb=$(ls "$cache"/linux-image-*-amd64_*.deb 2>/dev/null | head -1 || true)
  if [ -z "$deb" ]; then
    pkg=$(apt-cache depends linux-image-amd64 2>/dev/null | sed -n 's/.*Depends: \(linux-image-[0-9].*-amd64\)$/\1/p' | head -1)
    [ -n "$pkg" ] || skip "apt-cache cannot name the kernel package of linux-image-amd64 (apt-get update?)"
    (cd "$cache" && apt-get download "$pkg" >/dev/null 2>&1) || skip "apt-get download $pkg failed (offline?)"
    deb=$(ls "$cache"/linux-image-*-amd64_*.deb | head -1)
  fi
  rm -rf "$cache/k" && mkdir -p "$cache/k"
  dpkg-deb --fsys-tarfile "$deb" | tar -x -C "$cache/k" --wildcards './boot/vmlinuz-*' \
    '*/net/can/can.ko*' '*/net/can/can-raw.ko*' '*/drivers/net/can/dev/can-dev.ko*' '*/drivers/net/can/vcan.ko*'
  for m in can can-raw can-dev vcan; do
    f=$(find "$cache/k" -name "$m.ko*" | head -1)
    case "$f" in
      *.xz) xz -dc "$f" > "$cache/$m.ko" ;;
      *.zst) zstd -dcq "$f" > "$cache/$m.ko" ;;
      *) cp "$f" "$cache/$m.ko" ;;
    esac
  done
  cp "$cache"/k/boot/vmlinuz-* "$cache/vmlinuz"
  rm -rf "$cache/k"
fi
if [ ! -x "$cache/mkvcan" ] || [ "$here/tests/canopen/qemu/mkvcan.c" -nt "$cache/mkvcan" ]; then
  gcc -static -O2 -o "$cache/mkvcan" "$here/tests/canopen/qemu/mkvcan.c"
fi

# --- initramfs ----------------------------------------------------------------
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
root="$work/root"
mkdir -p "$root/bin" "$root/lib/modules" "$root/etc" "$root/proc" "$root/sys" "$root/dev" "$root/tmp"
cp "$bb" "$root/bin/busybox"
cp "$cache/mkvcan" "$root/bin/"
for m in can can-raw can-dev vcan; do cp "$cache/$m.ko" "$root/lib/modules/"; done
for app in "$build/apps/manip_fake_drive" "$build/apps/manip_can_check" "$build/apps/manip_rt" "$build/tests/canopen/qemu/manip_vcan_session"; do
  cp "$app" "$root/bin/"
  for lib in $(ldd "$app" | awk '/=>/ {print $3} /ld-linux/ {print $1}'); do
    mkdir -p "$root$(dirname "$lib")"
    [ -e "$root$lib" ] || cp "$lib" "$root$lib"
  done
done
cp "$here/tests/canopen/qemu/guest_bus_2k.yml" "$root/etc/bus.yml"
# Broken set-ups for manip_can_check: stage_y's drive missing (configured on
# vcan2, nobody there; boot deadline 0.5 s), or configured with a wrong node id.
sed -e 's/bus_y: {interface: vcan1/bus_y: {interface: vcan2/' -e 's/boot_timeout_ms: 5000/boot_timeout_ms: 500/' \
  "$here/tests/canopen/qemu/guest_bus_2k.yml" > "$root/etc/missing.yml"
sed -e 's/node_id: 2, workspace_axis: 1/node_id: 3, workspace_axis: 1/' \
  "$here/tests/canopen/qemu/guest_bus_2k.yml" > "$root/etc/wrongid.yml"
# manip_rt --backend can against the drive processes: the guest's bus file
# with no force sensor and the raw traffic recorded; rt.yaml with the
# sample-staleness and overrun limits widened (the emulated guest stalls for
# tens of ms; both policies are unit-tested), everything else as shipped.
{ cat "$here/tests/canopen/qemu/guest_bus_2k.yml"; printf 'backend:\n  force_sensor: none\n  record_raw_frames: true\n'; } > "$root/etc/rt_can.yml"
sed -e 's/^\(  stale_cycles:\) *[0-9]*/\1 4000/' -e 's/^\(  overrun_fault_consecutive:\) *[0-9]*/\1 1000000/' \
    -e 's/^\(  overrun_fault_per_second:\) *[0-9]*/\1 10000/' "$here/config/rt.yaml" > "$root/etc/rt.yaml"
grep -q "stale_cycles: 4000" "$root/etc/rt.yaml" && grep -q "overrun_fault_consecutive: 1000000" "$root/etc/rt.yaml" ||
  { echo "qemu vcan test: FAIL: could not derive the guest rt.yaml from config/rt.yaml"; exit 1; }
grep -q vcan2 "$root/etc/missing.yml" && grep -q "node_id: 3" "$root/etc/wrongid.yml" ||
  { echo "qemu vcan test: FAIL: could not derive the broken set-ups from guest_bus_2k.yml"; exit 1; }
cat > "$root/init" <<INIT
#!/bin/busybox sh
/bin/busybox --install -s /bin
mount -t proc proc /proc; mount -t sysfs sys /sys; mount -t devtmpfs dev /dev
for m in can can-raw can-dev vcan; do insmod /lib/modules/\$m.ko || echo "GUEST insmod \$m failed"; done
mkvcan vcan0 && mkvcan vcan1 && mkvcan vcan2 || echo "GUEST mkvcan failed"
# SYNC-loss alarm off in the drives: the emulated guest stalls for tens of
# ms at times (host steal time); that alarm is unit-tested on the virtual bus.
manip_fake_drive --iface vcan0 --node 1 --sync-loss-limit 0 > /tmp/d1.log 2>&1 &
manip_fake_drive --iface vcan1 --node 2 --sync-loss-limit 0 > /tmp/d2.log 2>&1 &
sleep 1
manip_vcan_session --config /etc/bus.yml --duration $duration --min-rate-fraction ${MANIP_VCAN_MIN_RATE:-0.3} --sync-median-max 1.5
echo "GUEST_EXIT=\$?"
# Across processes: the commissioning check against the drive processes.
manip_can_check --config /etc/bus.yml --periods 400 > /tmp/cc.log 2>&1; echo "CANCHECK good rc=\$?"
sed 's/^/CANCHECK good: /' /tmp/cc.log | grep -E "node [0-9]+:|OK|FAIL" | tail -4
manip_can_check --config /etc/missing.yml --periods 400 > /tmp/cc.log 2>&1; echo "CANCHECK missing rc=\$?"
sed 's/^/CANCHECK missing: /' /tmp/cc.log | grep -E "FAIL|never" | tail -2
manip_can_check --config /etc/wrongid.yml --periods 400 > /tmp/cc.log 2>&1; echo "CANCHECK wrongid rc=\$?"
sed 's/^/CANCHECK wrongid: /' /tmp/cc.log | grep -E "FAIL|unexpected" | tail -2
# manip_rt --backend can, paced (SCHED_FIFO in the guest), 2 s of loop time.
manip_rt --backend can --can-config /etc/rt_can.yml --config /etc/rt.yaml --realtime --duration 2 \
  --out /tmp/rt.lcm --lcm-url none > /tmp/rt.log 2>&1; echo "MANIP_RT rc=\$?"
sed 's/^/MANIP_RT: /' /tmp/rt.log | grep -vE "^MANIP_RT:   +(frame|SYNC|RPDO|TPDO|heartbeat|EMCY|cyclic|total)|^MANIP_RT: bus " | tail -14
tail -2 /tmp/d1.log /tmp/d2.log
poweroff -f
INIT
chmod +x "$root/init"
cpio=$(command -v cpio || echo "$bb cpio")  # busybox's cpio writes newc too
(cd "$root" && find . | $cpio -o -H newc 2>/dev/null | gzip -1) > "$work/initrd.gz"

# --- boot ---------------------------------------------------------------------
out="$work/console.log"
t0=$(date +%s)
timeout 300 qemu-system-x86_64 ${MANIP_QEMU_ACCEL:--accel tcg,thread=multi} -m 512 ${MANIP_QEMU_SMP:--smp 3} -nographic -no-reboot \
  -kernel "$cache/vmlinuz" -initrd "$work/initrd.gz" \
  -append "console=ttyS0 quiet panic=-1 no_timer_check" > "$out" 2>&1 || true
t1=$(date +%s)
tr -d '\r' < "$out" | grep -E "^(bus |  |start-up|cyclic|FAULT|disable|shutdown|VCAN_RESULT|GUEST|CANCHECK|MANIP_RT|node [12]:|==>)" || true
echo "qemu run: $((t1 - t0)) s wall"
con=$(tr -d '\r' < "$out")
fail=""
echo "$con" | grep -q "^VCAN_RESULT PASS" || fail="$fail protocol"
# manip_can_check across processes: 0 on the good set-up, 8 with the reason on the broken ones
echo "$con" | grep -q "^CANCHECK good rc=0$" || fail="$fail can_check-good"
echo "$con" | grep -q "^CANCHECK good: OK: the bus is ready" || fail="$fail can_check-good-report"
echo "$con" | grep -q "^CANCHECK missing rc=8$" || fail="$fail can_check-missing"
echo "$con" | grep -q "^CANCHECK missing: .*node 2: node never booted" || fail="$fail can_check-missing-reason"
echo "$con" | grep -q "^CANCHECK wrongid rc=8$" || fail="$fail can_check-wrongid"
echo "$con" | grep -q "^CANCHECK wrongid: .*unexpected node id" || fail="$fail can_check-wrongid-reason"
# manip_rt --backend can across processes: the duration reached without a fault, the traffic logged
echo "$con" | grep -q "^MANIP_RT rc=0$" || fail="$fail manip_rt"
echo "$con" | grep -q "^MANIP_RT: manip_rt: duration reached" || fail="$fail manip_rt-duration"
echo "$con" | grep -Eq "^MANIP_RT:   raw CAN frames: [1-9][0-9]* logged on MANIP_CAN_RAW in [0-9]+ batches, 0 dropped" || fail="$fail manip_rt-raw"
if [ -z "$fail" ]; then echo "qemu vcan test: PASS"; exit 0; fi
echo "qemu vcan test: FAIL:$fail"; echo "$con" | tail -40
exit 1
