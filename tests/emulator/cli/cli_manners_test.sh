#!/usr/bin/env bash
# What `wheelhil` says to a person: the help with no subcommand, the artefact list of
# `run --help`, the private bus a run announces and `exec --runtime-dir` attaching to it (a
# can-utils candump reads the run's frames), and the bash completion generated from the CLI.
# Usage: cli_manners_test.sh WHEELHIL SOURCE_DIR
set -euo pipefail
wheelhil="$1"
src="$2"
tmp="$(mktemp -d /tmp/wheelhil-cli-test.XXXXXX)"
run_pid=""
trap '[ -n "$run_pid" ] && kill "$run_pid" 2>/dev/null; rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

# 1. No subcommand: the help, on stdout, exit 0.
rc=0; "$wheelhil" >"$tmp/help" 2>"$tmp/help.err" || rc=$?
[ "$rc" -eq 0 ] || fail "wheelhil with no arguments exited $rc: $(cat "$tmp/help.err")"
for word in Subcommands: run campaign smoke bus exec completion; do
  grep -q "$word" "$tmp/help" || fail "the no-argument help does not mention '$word'"
done

# 2. run --help lists the artefacts.
"$wheelhil" run --help >"$tmp/run-help"
for a in can.log report.json report.html events.jsonl truth.csv estimate.csv firmware.log; do
  grep -q "$a" "$tmp/run-help" || fail "wheelhil run --help does not list $a"
done

# 3. A run on its private bus says where the bus is; candump attaches there and reads frames.
"$wheelhil" run "$src/scenarios/smoke/paper002_ortho3_short.yaml" --realtime --out "$tmp/run" \
  >"$tmp/run.out" 2>"$tmp/run.err" &
run_pid=$!
line=""
for _ in $(seq 100); do
  line="$(grep -m1 'private userspace bus in' "$tmp/run.err" || true)"
  [ -n "$line" ] && break
  sleep 0.1
done
[ -n "$line" ] || fail "the run did not announce its private bus: $(cat "$tmp/run.err")"
dir="$(sed -E 's/.*private userspace bus in ([^;]+);.*/\1/' <<<"$line")"
bus="$(sed -E 's/.*the firmware.s bus is ([^,]+),.*/\1/' <<<"$line")"
[ -d "$dir" ] || fail "announced runtime dir '$dir' does not exist"
grep -q -- "wheelhil exec --runtime-dir $dir -- candump -L $bus" <<<"$line" ||
  fail "the announcement does not give the attach command: $line"
if command -v candump >/dev/null; then
  timeout 20 "$wheelhil" exec --runtime-dir "$dir" -- candump -L -n 20 "$bus" >"$tmp/candump" ||
    fail "candump on the run's bus: rc $?"
  n="$(grep -cE "^\([0-9]+\.[0-9]{6}\) $bus [0-9A-F]{3,8}#" "$tmp/candump" || true)"
  [ "$n" -eq 20 ] || fail "candump read $n frames of 20 from the run's bus: $(head -3 "$tmp/candump")"
fi
rc=0; wait "$run_pid" || rc=$?
run_pid=""
# In real time the firmware's SYNC runs on the host's clock, so the verdict (exit 1: an
# expectation failed) depends on the host's load; anything else is a fault of the run.
[ "$rc" -eq 0 ] || [ "$rc" -eq 1 ] || fail "the watched run exited $rc: $(tail -5 "$tmp/run.err")"
# Once the run is over, its bus is gone, and exec says so.
rc=0; "$wheelhil" exec --runtime-dir "$dir" -- true 2>"$tmp/gone.err" || rc=$?
[ "$rc" -eq 1 ] || fail "exec --runtime-dir on an ended run exited $rc"
grep -q "no userspace bus runs in $dir" "$tmp/gone.err" || fail "unclear message: $(cat "$tmp/gone.err")"
# --quiet announces nothing.
"$wheelhil" run "$src/scenarios/smoke/paper002_ortho3_short.yaml" --quiet --out "$tmp/q" 2>"$tmp/q.err" ||
  fail "quiet run failed"
[ ! -s "$tmp/q.err" ] || fail "--quiet printed: $(cat "$tmp/q.err")"

# 4. Bash completion from the CLI definition.
"$wheelhil" completion bash >"$tmp/completion.bash"
complete_words() {  # the words typed so far, the last one being completed
  bash -c 'source "$1"; shift; COMP_WORDS=("$@"); COMP_CWORD=$(($# - 1)); _wheelhil
           printf "%s\n" "${COMPREPLY[@]}"' _ "$tmp/completion.bash" "$@" | sort | tr '\n' ' '
}
[ "$(complete_words wheelhil ru)" = "run " ] || fail "completing 'ru': $(complete_words wheelhil ru)"
[ "$(complete_words wheelhil bus "")" = "down list up " ] ||
  fail "completing 'bus ': $(complete_words wheelhil bus "")"
[ "$(complete_words wheelhil run x.yaml --clo)" = "--clock " ] ||
  fail "completing 'run --clo': $(complete_words wheelhil run x.yaml --clo)"
[ "$(complete_words wheelhil run x.yaml --clock "")" = "virtual " ] ||
  fail "completing 'run --clock ': $(complete_words wheelhil run x.yaml --clock "")"
[ "$(complete_words wheelhil exec --runtime-d)" = "--runtime-dir " ] ||
  fail "completing 'exec --runtime-d': $(complete_words wheelhil exec --runtime-d)"
echo "cli manners: help, run --help, private-bus announcement + attach, completion: ok"
