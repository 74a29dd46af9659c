#!/usr/bin/env bash
# The shipped URDF and SDF robots drive their scenarios to the same run as their hand-written
# YAML twins: each scenarios/urdf/*_{urdf,sdf}.yaml against the smoke scenario it copies (the same text but
# the platform line), every artefact of physics, bus and firmware byte-identical, both passing.
# Usage: urdf_twins.sh WHEELHIL_BIN SOURCE_DIR
set -uo pipefail
wheelhil=$1
src=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
status=0
for pair in paper000_slip_short:paper000_slip_short_urdf paper001_omni_short:paper001_omni_short_urdf \
            paper000_slip_short:paper000_slip_short_sdf; do
  yaml=${pair%%:*}
  urdf=${pair##*:}
  "$wheelhil" run "$src/scenarios/smoke/$yaml.yaml" --out "$work/$yaml" >"$work/$yaml.log" 2>&1
  rc_yaml=$?
  "$wheelhil" run "$src/scenarios/urdf/$urdf.yaml" --out "$work/$urdf" >"$work/$urdf.log" 2>&1
  rc_urdf=$?
  if [ "$rc_yaml" -ne 0 ] || [ "$rc_urdf" -ne 0 ]; then
    echo "FAIL: $yaml exit $rc_yaml, $urdf exit $rc_urdf (want 0, both passing)"
    tail -5 "$work/$yaml.log" "$work/$urdf.log"
    status=1
    continue
  fi
  for f in truth.csv can.log estimate.csv events.jsonl; do
    if cmp -s "$work/$yaml/$f" "$work/$urdf/$f"; then
      echo "ok: $urdf/$f = $yaml/$f ($(wc -l <"$work/$urdf/$f") lines)"
    else
      echo "FAIL: $urdf/$f differs from $yaml/$f: $(cmp "$work/$yaml/$f" "$work/$urdf/$f")"
      status=1
    fi
  done
done
exit $status
