#!/usr/bin/env bash
# End-to-end test of the wheelhil-fw program on the userspace CAN bus: the recorded device trace
# tests/data/firmware/paper000_devices.log (written by fw_device_trace_test.cc from the device
# behaviour) is replayed with can-utils canplayer through `wheelhil exec` while the real
# wheelhil-fw binary runs on the same bus. Twice. Passes when both runs put exactly the output
# frames of tests/data/firmware/paper000_expected_outputs.txt on the bus (same frames, same
# order: determinism, and the program agrees with the in-process app) and wheelhil-fw exits 0
# on SIGINT. Exit 77 (skip) without canplayer.
# Usage: fw_ucan_replay.sh WHEELHIL_BIN WHEELHIL_FW_BIN SOURCE_DIR
set -euo pipefail
wheelhil=$1
fw=$2
src=$3
if ! command -v canplayer >/dev/null; then
  echo "SKIP: canplayer (can-utils) not installed"
  exit 77
fi
data=$src/tests/data/firmware
work=$(mktemp -d)
export WHEELHIL_UCAN_DIR=$work/run
cleanup() {
  "$wheelhil" bus down ucan0 >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT

run() {
  local n=$1
  "$wheelhil" exec --bus ucan0 -- bash -c '
    "$1" --can ucan0 --config "$2" --log "$3" --quiet & fw=$!
    sleep 0.5
    canplayer -I "$4" ucan0=vcan0
    sleep 0.3
    kill -INT "$fw"
    wait "$fw"' _ "$fw" "$data/paper000_ucan.yaml" "$work/fw$n.log" "$data/paper000_devices.log"
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
