#!/usr/bin/env bash
# `wheelhil run` interrupted: SIGINT ends the run as a failure (exit 1, report.json names the
# signal, can.log kept, firmware gone, private bus directory removed); after SIGKILL the
# firmware dies with the run (PR_SET_PDEATHSIG) and the next run removes the directory left.
# Real time (--realtime), so that the run is still going when the signal comes.
# Usage: run_interrupt.sh WHEELHIL_BIN SOURCE_DIR
set -uo pipefail
wheelhil=$1
src=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
export TMPDIR=$work/tmp
mkdir -p "$TMPDIR"
scenario=$src/scenarios/paper000_slip.yaml
fail() { echo "FAIL: $*"; exit 1; }

# Processes whose environment names the bus directory $1.
on_bus() {
  grep -lsaF "WHEELHIL_UCAN_DIR=$1" /proc/[0-9]*/environ 2>/dev/null | grep -v "/proc/$$/" || true
}
wait_started() {  # the firmware is on the bus: its log and the run's directory exist
  for _ in $(seq 100); do
    dir=$(ls -d "$TMPDIR"/wheelhil-run-* 2>/dev/null | head -1)
    [ -n "$dir" ] && [ -n "$(on_bus "$dir")" ] && [ -e "$1/firmware.log" ] && return 0
    sleep 0.1
  done
  fail "the run did not start in 10 s"
}

"$wheelhil" run "$scenario" --realtime --quiet --out "$work/int" >"$work/int.log" 2>&1 &
pid=$!
wait_started "$work/int"
sleep 1
kill -INT $pid
wait $pid
rc=$?
[ "$rc" -eq 1 ] || fail "SIGINT: rc $rc, want 1: $(cat "$work/int.log")"
grep -q '"failure": "interrupted by signal 2 (SIGINT)"' "$work/int/report.json" ||
  fail "SIGINT: report.json does not name the signal"
[ -s "$work/int/can.log" ] || fail "SIGINT: can.log is empty"
[ -z "$(ls -d "$TMPDIR"/wheelhil-run-* 2>/dev/null)" ] || fail "SIGINT: runtime directory left"
[ -z "$(on_bus "$dir")" ] || fail "SIGINT: firmware left running"
echo "ok: SIGINT: rc 1, failure named, $(wc -l <"$work/int/can.log") frames kept, nothing left"

"$wheelhil" run "$scenario" --realtime --quiet --out "$work/kill" >/dev/null 2>&1 &
pid=$!
wait_started "$work/kill"
kill -KILL $pid
wait $pid 2>/dev/null
for _ in $(seq 50); do [ -z "$(on_bus "$dir")" ] && break; sleep 0.1; done
[ -z "$(on_bus "$dir")" ] || fail "SIGKILL: the firmware outlived the run"
[ -d "$dir" ] || fail "SIGKILL: expected the runtime directory to be left"
touch -d '1 minute ago' "$dir"  # older than a run that is just starting
"$wheelhil" run "$src/scenarios/smoke/paper000_slip_short.yaml" --quiet --out "$work/next" \
  >/dev/null 2>&1
[ ! -e "$dir" ] || fail "the next run did not remove $dir"
echo "ok: SIGKILL: firmware gone with the run, its directory removed by the next run"
