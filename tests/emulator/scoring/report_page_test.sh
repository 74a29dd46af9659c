#!/usr/bin/env bash
# report.html in a real browser: runs a smoke scenario, opens its report in headless Chromium
# (Debian's chromium, no network), requires that every script ran (the replay sets
# data-replay-ready on <body>; window.onerror would set data-script-errors) and takes a
# screenshot (left as report.png next to the report when KEEP_DIR is set).
# Usage: report_page_test.sh WHEELHIL SOURCE_DIR   (exit 77: no chromium)
set -euo pipefail
wheelhil="$1"
src="$2"
command -v chromium >/dev/null || { echo "chromium not installed (./hil setup)"; exit 77; }
tmp="$(mktemp -d /tmp/wheelhil-report-test.XXXXXX)"
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }
"$wheelhil" run "$src/scenarios/smoke/paper000_slip_short.yaml" --out "$tmp/run" --quiet ||
  fail "the scenario did not pass"
page="file://$tmp/run/report.html"
chrome=(chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run
        --disable-background-networking --disable-component-update --disable-sync
        --hide-scrollbars)
timeout 60 "${chrome[@]}" --user-data-dir="$tmp/profile1" --virtual-time-budget=3000 \
  --dump-dom "$page" >"$tmp/dom.html" 2>"$tmp/chromium.log" ||
  { tail -5 "$tmp/chromium.log" >&2; fail "chromium --dump-dom"; }
body="$(grep -o '<body[^>]*>' "$tmp/dom.html" | head -1)"
grep -q 'data-script-errors' <<<"$body" && fail "script errors in the page: $body"
grep -q 'data-replay-ready="1"' <<<"$body" || fail "the replay did not draw: $body"
grep -q '<canvas id="replay"' "$tmp/dom.html" || fail "no replay canvas"
[ "$(grep -c '<svg' "$tmp/dom.html")" -ge 3 ] || fail "fewer than 3 plots"
grep -q 'class="band"' "$tmp/dom.html" || fail "no shaded slip or fault interval"
grep -q '>Bus load (100 ms bins, 500 kbit/s)<' "$tmp/dom.html" || fail "no bus-load timeline"
grep -qE '<td title="[^"]*">[0-9.]+ mm</td>' "$tmp/dom.html" || fail "no metric shown in mm"
timeout 60 "${chrome[@]}" --user-data-dir="$tmp/profile2" --window-size=1000,2400 \
  --screenshot="$tmp/report.png" "$page" 2>>"$tmp/chromium.log" || fail "chromium --screenshot"
[ "$(head -c 8 "$tmp/report.png" | od -An -tx1 | tr -d ' ')" = 89504e470d0a1a0a ] ||
  fail "the screenshot is not a PNG"
size="$(stat -c %s "$tmp/report.png")"
[ "$size" -gt 50000 ] || fail "the screenshot is nearly empty ($size bytes)"
if [ -n "${KEEP_DIR:-}" ]; then cp "$tmp/report.png" "$tmp/run/report.html" "$KEEP_DIR/"; fi
echo "report page: scripts ran, replay drawn, screenshot $size bytes"
