#!/usr/bin/env bash
# `wheelhil run` options that cannot be exit 2 naming the fix: the retired cooperative clock
# (what replaced it); a --runahead that is neither on nor off; a --clock that is not virtual.
# (Malformed files: malformed_inputs.sh.)
# Usage: run_input_errors.sh WHEELHIL_BIN SOURCE_DIR
set -uo pipefail
wheelhil=$1
src=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# The cooperative clock was retired: exit 2 saying what replaced it.
"$wheelhil" run "$src/scenarios/smoke/paper000_slip_short.yaml" --clock cooperative \
  --out "$work/out2" >"$work/log2" 2>&1
rc=$?
want="--clock cooperative: the cooperative FW_Status handshake was retired: lockstep runs any firmware on its own virtual clock"
if [ "$rc" -ne 2 ] || ! grep -qF -- "$want" "$work/log2"; then
  echo "FAIL: --clock cooperative: rc $rc (want 2 and '$want'); output:"
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

# --clock takes virtual (cooperative is refused above): anything else exits 2 naming it.
"$wheelhil" run "$src/scenarios/smoke/paper000_slip_short.yaml" --clock fast \
  --out "$work/out4" >"$work/log4" 2>&1
rc=$?
want="--clock: 'fast' is not virtual"
if [ "$rc" -ne 2 ] || ! grep -qF -- "$want" "$work/log4"; then
  echo "FAIL: --clock fast: rc $rc (want 2 and '$want'); output:"
  cat "$work/log4"
  exit 1
fi
echo "ok: rc $rc: $(head -1 "$work/log4")"
