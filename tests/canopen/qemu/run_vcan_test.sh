#!/bin/sh
# Protocol test of the SocketCAN path (not run by ctest): boots a Debian
# kernel under qemu (software emulation), creates vcan0, runs two
# manip_fake_drive processes and manip_can_check against them, then the same
# with a drive that never boots. Needs: qemu-system-x86, busybox-static, the
# linux-image-<abi>-amd64 .deb (apt-get download), the built apps.
# Usage: tests/canopen/qemu/run_vcan_test.sh [build-dir] [kernel.deb]
set -eu
here=$(cd "$(dirname "$0")" && pwd)
build=${1:-$here/../../../build}
deb=${2:-$(ls /tmp/canqemu/linux-image-*-amd64_*.deb 2>/dev/null | head -1)}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/k" "$work/root/bin" "$work/root/lib/modules" "$work/root/etc"
dpkg-deb --fsys-tarfile "$deb" | tar -x -C "$work/k" --wildcards './boot/vmlinuz-*' \
  '*/net/can/can.ko*' '*/net/can/can-raw.ko*' '*/drivers/net/can/dev/can-dev.ko*' '*/drivers/net/can/vcan.ko*'
for m in can can-raw can-dev vcan; do
  f=$(find "$work/k" -name "$m.ko*" | head -1)
  case "$f" in
    *.xz) xz -dc "$f" > "$work/root/lib/modules/$m.ko" ;;
    *) cp "$f" "$work/root/lib/modules/$m.ko" ;;
  esac
done
cp /bin/busybox "$work/root/bin/busybox"
gcc -static -O2 -o "$work/root/bin/mkvcan" "$here/mkvcan.c"
for app in manip_fake_drive manip_can_check; do
  cp "$build/apps/$app" "$work/root/bin/"
  for lib in $(ldd "$build/apps/$app" | awk '/=>/ {print $3} /ld-linux/ {print $1}'); do
    mkdir -p "$work/root$(dirname "$lib")"
    cp -n "$lib" "$work/root$lib" 2>/dev/null || true
  done
done
cp "$here/guest_bus.yml" "$work/root/etc/bus.yml"
cat > "$work/root/init" <<'INIT'
#!/bin/busybox sh
/bin/busybox --install -s /bin
mount -t proc proc /proc; mount -t sysfs sys /sys; mount -t devtmpfs dev /dev
for m in can can-raw can-dev vcan; do insmod /lib/modules/$m.ko || echo "insmod $m failed"; done
mkvcan vcan0
manip_fake_drive --iface vcan0 --node 1 > /tmp/d1.log 2>&1 &
manip_fake_drive --iface vcan0 --node 2 > /tmp/d2.log 2>&1 &
sleep 1
manip_can_check --config /etc/bus.yml --periods 200
echo "CHECK_GOOD_EXIT=$?"
kill %1 %2; sleep 1
manip_fake_drive --iface vcan0 --node 1 > /tmp/d1.log 2>&1 &
manip_fake_drive --iface vcan0 --node 2 --never-boot > /tmp/d2.log 2>&1 &
sleep 1
manip_can_check --config /etc/bus.yml --periods 200
echo "CHECK_NEVER_BOOT_EXIT=$?"
poweroff -f
INIT
chmod +x "$work/root/init"
mkdir -p "$work/root/proc" "$work/root/sys" "$work/root/dev" "$work/root/tmp"
cpio=$(command -v cpio || echo "busybox cpio")
(cd "$work/root" && find . | $cpio -o -H newc | gzip -1) > "$work/initrd.gz"
out="$work/console.log"
timeout 600 qemu-system-x86_64 -accel tcg -m 512 -nographic -no-reboot \
  -kernel "$work"/k/boot/vmlinuz-* -initrd "$work/initrd.gz" \
  -append "console=ttyS0 quiet panic=-1 no_timer_check" > "$out" 2>&1 || true
grep -E "CHECK_|FAIL|OK:|node [12]|socket|insmod|vcan0" "$out" || true
good=$(sed -n 's/.*CHECK_GOOD_EXIT=\([0-9]*\).*/\1/p' "$out")
bad=$(sed -n 's/.*CHECK_NEVER_BOOT_EXIT=\([0-9]*\).*/\1/p' "$out")
if [ "$good" = "0" ] && [ "$bad" = "3" ]; then echo "vcan protocol test: PASS"; exit 0; fi
echo "vcan protocol test: FAIL (good=$good never-boot=$bad)"; tail -40 "$out"; exit 1
