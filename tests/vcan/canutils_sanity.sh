#!/usr/bin/env bash
# Proves the vcan harness with third-party tools: inside the UML guest of uml_run.sh, candump
# must see exactly what cansend writes to vcan0 (classic, 29-bit, remote and CAN FD frames).
# Exit 77 (skip) without can-utils; outside a guest it needs an up vcan named by WHEELHIL_VCAN.
set -euo pipefail
iface="${WHEELHIL_VCAN:-vcan0}"
for tool in cansend candump; do
  command -v "$tool" > /dev/null || { echo "SKIP: $tool not installed (apt-get install can-utils)"; exit 77; }
done
[ -e "/sys/class/net/$iface" ] || { echo "SKIP: no interface $iface (run under tests/vcan/uml_run.sh)"; exit 77; }

frames=(123#DEADBEEF 1ABCDEF0#0102 7FF#R 321##1112233445566778899AABBCC)
# candump prints FD flags with CANFD_FDF (0x04), which cansend sets on FD frames: BRS -> 5.
expected=$(printf '%s\n' 123#DEADBEEF 1ABCDEF0#0102 7FF#R 321##5112233445566778899AABBCC)
out="$(mktemp)"
trap 'rm -f "$out"' EXIT
# -L: log format "(time) iface ID#DATA"; -n: stop after that many frames; -T: give up after 5 s.
candump -L -n "${#frames[@]}" -T 5000 "$iface" > "$out" &
dump=$!
sleep 0.3  # let candump bind before the first frame; it would otherwise miss it
for f in "${frames[@]}"; do cansend "$iface" "$f"; done
wait "$dump"
got="$(awk '{print $3}' "$out")"
echo "candump saw:"; cat "$out"
if [ "$got" != "$expected" ]; then
  echo "FAIL: expected"; echo "$expected"; exit 1
fi
# candump -L lines must name the interface and carry a timestamp.
awk -v i="$iface" '$2 != i || $1 !~ /^\([0-9]+\.[0-9][0-9][0-9][0-9][0-9][0-9]\)$/ {bad=1} END {exit bad}' "$out" \
  || { echo "FAIL: malformed candump -L line"; exit 1; }
echo "PASS: ${#frames[@]} frames through kernel $iface"
