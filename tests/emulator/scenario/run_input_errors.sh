#!/usr/bin/env bash
# `wheelhil run` options that contradict the scenario exit 2 naming the fix: a SYNC-producing
# firmware asked for in cooperative lockstep; a --runahead that is neither on nor off. (Malformed
# files: malformed_inputs.sh.)
# Usage: run_input_errors.sh WHEELHIL_BIN SOURCE_DIR
set -uo pipefail
wheelhil=$1
src=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# A SYNC-producing firmware in cooperative lockstep cannot be: exit 2 with the fix named.
"$wheelhil" run "$src/scenarios/smoke/paper000_slip_short.yaml" --clock cooperative \
  --sync-producer firmware --out "$work/out2" >"$work/log2" 2>&1
rc=$?
want="runs in lockstep only on the virtual clock, which this run does not have"
if [ "$rc" -ne 2 ] || ! grep -qF -- "$want" "$work/log2"; then
  echo "FAIL: --sync-producer firmware: rc $rc (want 2 and '$want'); output:"
  cat "$work/log2"
  exit 1
fi
echo "ok: rc $rc: $(cat "$work/log2")"

# --runahead takes on or off: anything else exits 2 naming both.
"$wheelhil" run "$src/scenarios/smoke/paper000_slip_short.yaml" --runahead maybe \
  --out "$work/out3" >"$work/log3" 2>&1
rc=$?
want="--runahead: maybe not in {auto,on,off}"
if [ "$rc" -ne 2 ] || ! grep -qF -- "$want" "$work/log3"; then
  echo "FAIL: --runahead maybe: rc $rc (want 2 and '$want'); output:"
  cat "$work/log3"
  exit 1
fi
echo "ok: rc $rc: $(head -1 "$work/log3")"
