#!/usr/bin/env bash
# wheelhil-fw's exit codes: 2 for a bad command line, config or DBC directory (message names
# file:line:col and field), 1 for an interface that cannot be opened (the transport's message),
# 0 on SIGTERM while running (on the userspace bus through `wheelhil exec`).
# Usage: fw_exit_codes.sh WHEELHIL_BIN WHEELHIL_FW_BIN SOURCE_DIR
set -uo pipefail
wheelhil=$1
fw=$2
src=$3
work=$(mktemp -d)
export WHEELHIL_UCAN_DIR=$work/run
trap '"$wheelhil" bus down ucan0 >/dev/null 2>&1; rm -rf "$work"' EXIT
good=$src/scenarios/firmware/paper000_diff_drive.yaml
fail=0

expect() {  # expect RC SUBSTRING -- command...
  local want=$1 text=$2
  shift 3
  "$@" > "$work/out" 2>&1
  local rc=$?
  if [ "$rc" -ne "$want" ] || ! grep -qF -- "$text" "$work/out"; then
    echo "FAIL: '$*' gave rc $rc (want $want) and:"; cat "$work/out"; echo "(wanted '$text')"
    fail=1
  else
    echo "ok: rc $rc: $(grep -F -- "$text" "$work/out" | head -1)"
  fi
}

sed 's/track_width_m: 0.5 /track_width_m: -0.5/' "$good" > "$work/bad.yaml"
line=$(grep -n 'track_width_m' "$work/bad.yaml" | cut -d: -f1)
expect 2 "bad.yaml:$line:18: paper000.track_width_m: (-0.5) must be > 0" -- \
  "$fw" --can ucan0 --config "$work/bad.yaml"
expect 2 "nonexistent.yaml:0:0: (file): cannot be read" -- \
  "$fw" --can ucan0 --config "$work/nonexistent.yaml"
expect 2 "--can is required" -- "$fw" --config "$good"
expect 2 "/nonexistent/cia406_encoder.dbc: DBC file not found" -- \
  "$fw" --can ucan0 --config "$good" --dbc-dir /nonexistent
expect 1 "wheelhilnone0" -- "$fw" --can wheelhilnone0 --config "$good"
expect 2 "--clock-rate: Value 0 not in range" -- "$fw" --can ucan0 --config "$good" --clock-rate 0
# Runs until SIGTERM, then exits 0. The signal goes once the firmware says it has started (its
# handlers are installed before that line), however slow the start-up (ASan, a loaded machine).
expect 0 "rc=0" -- "$wheelhil" exec --bus ucan0 -- bash -c \
  '"$0" --can ucan0 --config "$1" 2> "$2" & p=$!
   for i in $(seq 200); do grep -q "wheelhil-fw: estimator" "$2" && break; sleep 0.1; done
   sleep 0.2; kill -TERM $p; wait $p; echo "rc=$?"' \
  "$fw" "$good" "$work/fw_stderr"
exit $fail
