#!/usr/bin/env bash
# The customer firmwares (C, C++, Python; tests/customer_firmware/) in lockstep on the virtual
# clock over a kernel vcan0 (`wheelhil run ... --can vcan0`): every run passes its expectations,
# and each firmware gives the same can.log twice, byte for byte, and the same as on the private
# userspace bus.
# Runs inside the user-mode-linux guest (ctest -L vcan: Vcan.VirtualClockCustomerFirmwares).
# Usage: virtual_clock_customers.sh WHEELHIL SOURCE_DIR OUT_DIR
set -uo pipefail
wheelhil=$1 src=$2 out=$3
rm -rf "$out"
mkdir -p "$out"
fail=0
run() {  # name dir args...
  local name=$1 dir=$2
  shift 2
  "$wheelhil" run "$@" --out "$dir" --quiet >"$dir.txt" 2>&1
  local rc=$?
  if [ "$rc" -ne 0 ]; then
    echo "FAIL: $name: wheelhil run $* exited $rc:" >&2
    # On stderr: uml_run.sh tells a sanitizer build that cannot run in the guest from there.
    cat "$dir.txt" >&2
    fail=1
    return 1
  fi
}
for fw in c_epoll_odometry cpp_cv_odometry python_can_odometry; do
  scen="$src/tests/data/customer_firmware/$fw.yaml"
  run "$fw on vcan0" "$out/$fw-a" "$scen" --can vcan0 || continue
  run "$fw on vcan0, again" "$out/$fw-b" "$scen" --can vcan0 || continue
  run "$fw on the private bus" "$out/$fw-ucan" "$scen" || continue
  if ! grep -q '"clock":"virtual"' "$out/$fw-a/events.jsonl" ||
     ! grep -q '"bus":"socketcan"' "$out/$fw-a/events.jsonl"; then
    echo "FAIL: $fw: not on the virtual clock over the kernel bus: $(head -1 "$out/$fw-a/events.jsonl")"
    fail=1
  fi
  for r in a b; do
    if ! grep -q '"verdict": "pass"' "$out/$fw-$r/report.json"; then
      echo "FAIL: $fw: run $r did not pass: $(grep -m1 '"failure"' "$out/$fw-$r/report.json")"
      fail=1
    fi
  done
  if ! cmp -s "$out/$fw-a/can.log" "$out/$fw-b/can.log"; then
    echo "FAIL: $fw: two runs over vcan0 differ:"
    diff "$out/$fw-a/can.log" "$out/$fw-b/can.log" | head -5
    fail=1
  fi
  if ! sed 's/ ucan0 / vcan0 /' "$out/$fw-ucan/can.log" | cmp -s - "$out/$fw-a/can.log"; then
    echo "FAIL: $fw: vcan0 and the private bus differ:"
    sed 's/ ucan0 / vcan0 /' "$out/$fw-ucan/can.log" | diff - "$out/$fw-a/can.log" | head -5
    fail=1
  fi
  [ "$fail" = 0 ] && echo "ok: $fw: $(wc -l <"$out/$fw-a/can.log") frames, the same bytes twice and as on ucan0"
done
exit $fail
