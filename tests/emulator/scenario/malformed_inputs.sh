#!/usr/bin/env bash
# The malformed-input corpus: every file of tests/data/malformed (a scenario, run with `wheelhil
# run`) and of tests/data/malformed/campaign (`wheelhil campaign`) must end with exit 2 and the
# messages its first lines name (`# expect: TEXT`, each to be found; $DIR stands for the file's
# folder), within
# a 20 s wall-clock limit that only catches a hang. Then the inputs that cannot be committed:
# /dev/zero, a directory, a file past the size limit, a scenario with too many expectations, a
# DBC that is a FIFO and an EDS that is a directory.
# Usage: malformed_inputs.sh WHEELHIL_BIN SOURCE_DIR
set -uo pipefail
wheelhil=$1
src=$2
corpus=$src/tests/data/malformed
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
failures=0
cases=0

# check NAME WANTS COMMAND...: exit 2, each line of WANTS in the output, no signal, no hang.
check() {
  local name=$1 wants=$2
  shift 2
  cases=$((cases + 1))
  timeout -s KILL 20 "$@" >"$work/log" 2>&1
  local rc=$? missing=
  while IFS= read -r want; do
    grep -aqF -- "$want" "$work/log" || missing="$missing '$want'"
  done <<<"$wants"
  if [ "$rc" -ne 2 ] || [ -z "$wants" ] || [ -n "$missing" ]; then
    echo "FAIL $name: rc $rc (want 2 and$missing); output:"
    head -c 2000 "$work/log"
    echo
    failures=$((failures + 1))
  else
    echo "ok   $name: $(head -c 300 "$work/log" | tr '\n' ' ')"
  fi
}

expected() {
  sed -n '/^# expect: /!q; s/^# expect: //p' "$1" | sed "s#\$DIR#$(dirname "$1")#g"
}

for f in "$corpus"/*.yaml; do
  check "$(basename "$f")" "$(expected "$f")" "$wheelhil" run "$f" --out "$work/out"
done
for f in "$corpus"/campaign/*.yaml; do
  check "campaign/$(basename "$f")" "$(expected "$f")" \
    "$wheelhil" campaign "$f" --out "$work/campaign" --no-html
done

check /dev/zero "/dev/zero:0:0: (file): is not a regular file" \
  "$wheelhil" run /dev/zero --out "$work/out"
check directory "$work:0:0: (file): is a directory, not a YAML file" \
  "$wheelhil" run "$work" --out "$work/out"
big=$work/big.yaml
{ echo "name: big"; head -c $((17 << 20)) /dev/zero | tr '\0' '#'; } >"$big"
check oversized "$big:0:0: (file): is larger than 16 MiB" "$wheelhil" run "$big" --out "$work/out"
# A device description that is a FIFO (the load waited for a writer) or a directory.
mkfifo "$work/fifo.dbc"
mkdir "$work/dir.eds"
for kind in fifo_dbc dir_eds; do
  {
    echo "name: $kind"
    echo "platform: $src/scenarios/platforms/diff2.yaml"
    echo "motion: [{type: hold, duration_s: 0.5}]"
    echo "devices:"
    if [ "$kind" = fifo_dbc ]; then
      echo "  - {kind: dbc, name: imu, dbc: $work/fifo.dbc, node: Imu, signals: {Rate: rate_z}}"
    else
      echo "  - {kind: canopen_cia406, wheel: left, node_id: 1, eds: $work/dir.eds}"
      echo "  - {kind: canopen_cia406, wheel: right, node_id: 2, eds: $work/dir.eds}"
    fi
  } >"$work/$kind.yaml"
done
check fifo_dbc "$work/fifo.dbc:0: is not a regular file (a device or a pipe?)" \
  "$wheelhil" run "$work/fifo_dbc.yaml" --out "$work/out"
check dir_eds "$work/dir.eds:0: is a directory, not an EDS file" \
  "$wheelhil" run "$work/dir_eds.yaml" --out "$work/out"
many=$work/many_expectations.yaml
{
  sed -n '2,$p' "$corpus/seed_fraction.yaml" | sed -e '/^seed:/d' \
    -e "s#\.\./\.\./\.\./#$src/#"
  echo "expectations:"
  for _ in $(seq 10001); do echo '  - {metric: pose.final_position_error_m, "<": 1}'; done
} >"$many"
check many_expectations "expectations: 10001 entries; at most 10000 are supported" \
  "$wheelhil" run "$many" --out "$work/out"

echo "$((cases - failures))/$cases malformed inputs refused as input errors"
[ "$failures" -eq 0 ]
