#!/usr/bin/env bash
# End-to-end test of the wheelhil-fw program on the userspace CAN bus: the recorded device trace
# tests/data/firmware/paper000_devices.log (written by fw_device_trace_test.cc from the device
# behaviour) is replayed with can-utils canplayer through `wheelhil exec` while the real
# wheelhil-fw binary runs on the same bus. Twice. Passes when both runs put exactly the output
# frames of tests/data/firmware/paper000_expected_outputs.txt on the bus (same frames, same
# order: determinism, and the program agrees with the in-process app) and wheelhil-fw exits 0
# on SIGINT. Exit 77 (skip) without canplayer.
# Usage: fw_ucan_replay.sh [--kernel IFACE] WHEELHIL_BIN WHEELHIL_FW_BIN SOURCE_DIR
#   --kernel IFACE: run on an existing kernel interface (e.g. vcan0 in the user-mode-linux guest
#   of tests/vcan/uml_run.sh) instead of the userspace bus.
set -euo pipefail
kernel_iface=
if [ "${1:-}" = "--kernel" ]; then
  kernel_iface=$2
  shift 2
fi
wheelhil=$1
fw=$2
src=$3
if ! command -v canplayer >/dev/null; then
  echo "SKIP: canplayer (can-utils) not installed"
  exit 77
fi
data=$src/tests/data/firmware
work=$(mktemp -d "${FW_REPLAY_TMP:-/tmp}/fwreplay.XXXXXX")
export WHEELHIL_UCAN_DIR=$work/run
cleanup() {
  [ -n "$kernel_iface" ] || "$wheelhil" bus down ucan0 >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT

# shellcheck disable=SC2016 # the inner script expands its own positional parameters
body='"$1" --can "$5" --config "$2" --log "$3" --quiet & fw=$!
  for _ in $(seq 100); do [ -e "$3" ] && break; sleep 0.1; done  # Socket open, log created.
  sleep 0.2
  canplayer -I "$4" "$5"=vcan0
  sleep 0.3
  kill -INT "$fw"
  wait "$fw"'
run() {
  local n=$1
  local args=("$fw" "$data/paper000_ucan.yaml" "$work/fw$n.log" "$data/paper000_devices.log")
  if [ -n "$kernel_iface" ]; then
    bash -c "$body" _ "${args[@]}" "$kernel_iface"
  else
    "$wheelhil" exec --bus ucan0 -- bash -c "$body" _ "${args[@]}" ucan0
  fi
  # The firmware's output frames (ids 0x680..0x686), without timestamps.
  awk '$3 ~ /^68[0-6]#/ {print $3}' "$work/fw$n.log" > "$work/out$n.txt"
  echo "run $n: $(wc -l < "$work/out$n.txt") output frames"
}

run 1
run 2
status=0
if ! cmp -s "$work/out1.txt" "$work/out2.txt"; then
  echo "FAIL: the two runs differ"
  diff "$work/out1.txt" "$work/out2.txt" | head -20
  status=1
fi
if ! cmp -s "$work/out1.txt" "$data/paper000_expected_outputs.txt"; then
  echo "FAIL: outputs differ from $data/paper000_expected_outputs.txt"
  diff "$work/out1.txt" "$data/paper000_expected_outputs.txt" | head -20
  status=1
fi
[ $status -eq 0 ] && echo "PASS: identical outputs in both runs, equal to the expected file"
exit $status
