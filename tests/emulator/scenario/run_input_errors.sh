#!/usr/bin/env bash
# `wheelhil run` on a malformed scenario exits 2 with a located message (file:line:col: field:
# problem), never an abort. Case: scenarios/smoke/paper000_slip_short.yaml without its track_y_m
# line, a key missing inside a section (yaml-cpp reports that as YAML::InvalidNode); and a
# SYNC-producing firmware asked for in cooperative lockstep.
# Usage: run_input_errors.sh WHEELHIL_BIN SOURCE_DIR
set -uo pipefail
wheelhil=$1
src=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

scen="$work/no_track_y.yaml"
sed -e '/track_y_m/d' -e "s#\.\./platforms/#$src/scenarios/platforms/#" \
  -e "s#\.\./firmware/#$src/scenarios/firmware/#" \
  "$src/scenarios/smoke/paper000_slip_short.yaml" >"$scen"
# The random_patches mapping starts at its first key, the line after `random_patches:`.
line=$(($(grep -n 'random_patches:' "$scen" | cut -d: -f1) + 1))
"$wheelhil" run "$scen" --out "$work/out" >"$work/log" 2>&1
rc=$?
want="$scen:$line:5: terrain.random_patches.track_y_m: is required"
if [ "$rc" -ne 2 ] || ! grep -qF -- "$want" "$work/log"; then
  echo "FAIL: rc $rc (want 2 and '$want'); output:"
  cat "$work/log"
  exit 1
fi
echo "ok: rc $rc: $(cat "$work/log")"

# A SYNC-producing firmware in cooperative lockstep cannot be: exit 2 with the fix named.
"$wheelhil" run "$src/scenarios/smoke/paper000_slip_short.yaml" --sync-producer firmware \
  --out "$work/out2" >"$work/log2" 2>&1
rc=$?
want="runs in lockstep only on the virtual clock (--clock virtual, or --realtime)"
if [ "$rc" -ne 2 ] || ! grep -qF -- "$want" "$work/log2"; then
  echo "FAIL: --sync-producer firmware: rc $rc (want 2 and '$want'); output:"
  cat "$work/log2"
  exit 1
fi
echo "ok: rc $rc: $(cat "$work/log2")"
