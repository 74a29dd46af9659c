#!/usr/bin/env bash
# `wheelhil new DIR` makes a project that runs at once: its scenario passes with the reference
# firmware, its smoke list and its campaign run; a second `new` on it is refused (exit 2)
# unless --force; a DIR that is a file is refused. With --urdf / --sdf (the shipped paper-000
# robot's descriptions) platform.yaml reads the description and the scenario passes too; a
# robot that is not a differential drive is refused with its wheel joints named.
# Usage: new_project.sh WHEELHIL_BIN SOURCE_DIR
set -uo pipefail
wheelhil=$1
src=$2
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

"$wheelhil" new "$work/my_bot" >"$work/new.log" 2>&1 || fail "new: $(cat "$work/new.log")"
for f in platform.yaml scenario.yaml firmware.yaml outputs.yaml campaign.yaml smoke.list README.md; do
  [ -s "$work/my_bot/$f" ] || fail "new wrote no $f"
done
grep -q "^name: my_bot$" "$work/my_bot/platform.yaml" || fail "platform.yaml not named my_bot"
for f in platform scenario firmware outputs campaign; do
  line=$(head -1 "$work/my_bot/$f.yaml")
  schema=${line#\# yaml-language-server: \$schema=}
  [ "$schema" != "$line" ] && [ -s "$schema" ] || fail "$f.yaml: first line '$line' names no schema file"
done
# Each file is valid against the schema its first line names (an independent validator).
/usr/bin/python3 - "$work/my_bot" <<'PY' || fail "a skeleton file is not valid against its schema"
import json, re, sys, glob, jsonschema, yaml
yaml.SafeLoader.add_implicit_resolver("tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$"), list("-+0123456789."))
for path in sorted(glob.glob(sys.argv[1] + "/*.yaml")):
    text = open(path).read()
    schema = json.load(open(text.splitlines()[0].split("$schema=", 1)[1]))
    errors = list(jsonschema.Draft202012Validator(schema).iter_errors(yaml.safe_load(text)))
    if errors:
        print(path, list(errors[0].absolute_path), errors[0].message)
        sys.exit(1)
print("ok: every skeleton file valid against its schema")
PY
cd "$work/my_bot" || exit 1
"$wheelhil" run scenario.yaml --out run >"$work/run.log" 2>&1 || fail "run: $(tail -5 "$work/run.log")"
grep -q "verdict: pass" "$work/run.log" || fail "run did not pass: $(tail -5 "$work/run.log")"
"$wheelhil" smoke --scenarios smoke.list --junit smoke.xml --out smoke >"$work/smoke.log" 2>&1 ||
  fail "smoke: $(tail -5 "$work/smoke.log")"
grep -q "smoke: 1/1 passed" "$work/smoke.log" || fail "smoke: $(tail -3 "$work/smoke.log")"
"$wheelhil" campaign campaign.yaml -j 2 --out camp >"$work/camp.log" 2>&1 ||
  fail "campaign: $(tail -5 "$work/camp.log")"
echo "ok: new, run, smoke and campaign ($(grep -c . "$work/camp.log") lines of campaign output)"

"$wheelhil" new "$work/my_bot" >"$work/again.log" 2>&1
rc=$?
[ "$rc" -eq 2 ] && grep -q "is not empty (--force" "$work/again.log" || fail "second new: rc $rc: $(cat "$work/again.log")"
"$wheelhil" new --force "$work/my_bot" >/dev/null 2>&1 || fail "new --force"
touch "$work/file"
"$wheelhil" new "$work/file" >"$work/file.log" 2>&1
rc=$?
[ "$rc" -eq 2 ] && grep -q "exists and is not a directory" "$work/file.log" || fail "new on a file: rc $rc"
echo "ok: refusals"

for desc in "--urdf $src/scenarios/platforms/urdf/diff2.urdf" "--sdf $src/scenarios/platforms/sdf/diff2.sdf"; do
  rm -rf "$work/described"
  # shellcheck disable=SC2086
  "$wheelhil" new "$work/described" $desc >"$work/d.log" 2>&1 || fail "new $desc: $(cat "$work/d.log")"
  grep -q "joint: left_wheel_joint" "$work/described/platform.yaml" || fail "new $desc: no left wheel joint"
  (cd "$work/described" && "$wheelhil" run scenario.yaml --out run >"$work/drun.log" 2>&1) ||
    fail "run after new $desc: $(tail -5 "$work/drun.log")"
  grep -q "verdict: pass" "$work/drun.log" || fail "new $desc: the run did not pass"
  echo "ok: new $desc runs and passes"
done
"$wheelhil" new "$work/mecanum" --urdf "$src/scenarios/platforms/urdf/mecanum4_omni3.urdf" >"$work/m.log" 2>&1
rc=$?
[ "$rc" -eq 2 ] && grep -q "has 4 wheel joints with a fixed axle across the robot" "$work/m.log" ||
  fail "new on a Mecanum robot: rc $rc: $(cat "$work/m.log")"
echo "ok: a robot that is not a differential drive is refused with its joints named"
