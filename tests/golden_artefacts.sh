#!/usr/bin/env bash
# Golden-artefact check: runs every shipped scenario (scenarios/*.yaml, scenarios/smoke/*.yaml)
# at its default seed and compares the SHA-256 of its can.log, truth.csv, estimate.csv,
# events.jsonl and report.json (without its "wall" block: wall time, CPU) with the committed list
# tests/data/golden/artefacts.sha256. A refactor that claims "no change of behaviour" passes it.
#
#   tests/golden_artefacts.sh [--update] [--jobs N] [--keep DIR] BUILD_DIR
#     --update   write the list from this build instead of comparing (commit it with the change
#                that is meant to change the artefacts, and say why in the commit message)
#     --jobs N   scenarios run at once (default 1; lockstep runs are deterministic at any load)
#     --keep DIR leave the runs' output folders in DIR (default: a temporary folder, removed)
# Exit 0 all equal (or updated), 1 a difference (each listed with the files that differ), 2 usage.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
LIST="$ROOT/tests/data/golden/artefacts.sha256"
update=0 jobs=1 keep="" build=""
while [ $# -gt 0 ]; do
  case "$1" in
    --update) update=1 ;;
    --jobs) jobs="$2"; shift ;;
    --keep) keep="$2"; shift ;;
    -h|--help) sed -n '2,13p' "$0"; exit 0 ;;
    -*) echo "golden_artefacts: unknown option $1" >&2; exit 2 ;;
    *) build="$1" ;;
  esac
  shift
done
if [ -z "$build" ] || [ ! -x "$build/bin/wheelhil" ]; then
  echo "golden_artefacts: usage: $0 [--update] [--jobs N] BUILD_DIR (no $build/bin/wheelhil)" >&2
  exit 2
fi
wheelhil="$(cd "$build/bin" && pwd)/wheelhil"
if [ -n "$keep" ]; then
  mkdir -p "$keep"; out="$(cd "$keep" && pwd)"
else
  out="$(mktemp -d /tmp/wheelhil-golden-XXXXXX)"
  trap 'rm -rf "$out"' EXIT
fi

cd "$ROOT"
scenarios=(scenarios/*.yaml scenarios/smoke/*.yaml)
run_one() {
  local scen="$1" name
  name="$(echo "${scen%.yaml}" | tr '/' '_')"
  # The verdict is not the point here (exit 1 is a failed expectation); a crash or an input
  # error is (exit >= 2), and shows as missing artefacts.
  "$wheelhil" run "$scen" --out "$out/$name" >"$out/$name.stdout" 2>&1 || true
}
export -f run_one
export wheelhil out
printf '%s\n' "${scenarios[@]}" | xargs -P "$jobs" -I{} bash -c 'run_one "$@"' _ {}

# One line per artefact: "<sha256>  <scenario>/<file>", "missing" for an artefact not written.
actual="$out/actual.sha256"
: >"$actual"
for scen in "${scenarios[@]}"; do
  name="$(echo "${scen%.yaml}" | tr '/' '_')"
  dir="$out/$name"
  for f in can.log truth.csv estimate.csv events.jsonl report.json; do
    if [ ! -f "$dir/$f" ]; then
      echo "missing  $scen/$f" >>"$actual"
    elif [ "$f" = report.json ]; then
      # report.json is written with sorted keys and two-space indentation: "wall" is the last
      # top-level block.
      sum="$(sed '/^  "wall": {$/,/^  }$/d' "$dir/$f" | sha256sum | cut -d' ' -f1)"
      echo "$sum  $scen/$f" >>"$actual"
    else
      echo "$(sha256sum <"$dir/$f" | cut -d' ' -f1)  $scen/$f" >>"$actual"
    fi
  done
done

if [ "$update" = 1 ]; then
  cp "$actual" "$LIST"
  echo "golden_artefacts: wrote $(wc -l <"$LIST") hashes of ${#scenarios[@]} scenarios to $LIST"
  exit 0
fi
if [ ! -f "$LIST" ]; then
  echo "golden_artefacts: no list $LIST (run with --update first)" >&2
  exit 2
fi
if diff -u "$LIST" "$actual" >"$out/diff.txt"; then
  echo "golden_artefacts: ${#scenarios[@]} scenarios, $(wc -l <"$LIST") artefacts byte-identical"
  exit 0
fi
echo "golden_artefacts: artefacts differ from $LIST (- committed, + this build):" >&2
grep '^[-+][^-+]' "$out/diff.txt" >&2 || true
# What each such run said (a timeout under load and a change of behaviour look different).
for scen in $(grep '^+[^+]' "$out/diff.txt" | awk '{print $2}' | sed 's|/[^/]*$||' | sort -u); do
  name="$(echo "${scen%.yaml}" | tr '/' '_')"
  [ -f "$out/$name.stdout" ] && { echo "--- $scen: the run's last lines:" >&2; tail -5 "$out/$name.stdout" >&2; }
done
[ -n "$keep" ] || echo "golden_artefacts: rerun with --keep DIR to look at the runs" >&2
exit 1
