#!/usr/bin/env bash
# The Debian package on a fresh Debian 12: bootstraps a minimal bookworm root (debootstrap,
# deb.debian.org), installs wheelhil_*.deb there with apt-get (the command the Containerfile
# runs), then inside it (chroot, as root) runs the installed paper-000 scenario and requires the
# verdict "pass", runs the no-argument help, and checks the bash completion is installed.
# Usage: deb_fresh_root_test.sh DIR_WITH_DEBS   (root; `./hil package --check` runs it)
set -euo pipefail
debs="$(cd "$1" && pwd)"
root="$debs/debian12-root"
mirror="${WHEELHIL_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
fail() { echo "FAIL: $*" >&2; exit 1; }
log() { printf 'deb check: %s\n' "$*" >&2; }
[ "$(id -u)" -eq 0 ] || fail "needs root (debootstrap, chroot)"
deb="$(ls "$debs"/wheelhil_*_amd64.deb 2>/dev/null | head -1)"
[ -n "$deb" ] || fail "no wheelhil_*_amd64.deb in $debs (run ./hil package)"

cleanup() {
  for m in proc dev/pts dev; do mountpoint -q "$root/$m" && umount -l "$root/$m"; done
  return 0
}
trap cleanup EXIT
cleanup
rm -rf "$root"
log "debootstrap --variant=minbase bookworm $root ($mirror)"
t0=$SECONDS
debootstrap --variant=minbase bookworm "$root" "$mirror" >"$debs/debootstrap.log" 2>&1 ||
  { tail -20 "$debs/debootstrap.log" >&2; fail "debootstrap"; }
log "fresh root in $((SECONDS - t0)) s: $(cat "$root/etc/debian_version")"
mount -t proc proc "$root/proc"
mount --bind /dev "$root/dev"
mount --bind /dev/pts "$root/dev/pts"
cp /etc/resolv.conf "$root/etc/resolv.conf" 2>/dev/null || true
cp "$deb" "$root/tmp/"
in_root() { chroot "$root" /usr/bin/env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin HOME=/root "$@"; }

t0=$SECONDS
log "apt-get install ./$(basename "$deb")"
in_root sh -c "apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q \
  --no-install-recommends /tmp/$(basename "$deb")" >"$debs/apt.log" 2>&1 ||
  { tail -30 "$debs/apt.log" >&2; fail "apt-get install of the package"; }
log "installed in $((SECONDS - t0)) s: $(in_root dpkg-query -W -f='${Package} ${Version}, ${Installed-Size} KiB' wheelhil)"

in_root wheelhil version
in_root wheelhil >"$debs/help.txt" || fail "wheelhil with no arguments failed"
grep -q "run" "$debs/help.txt" || fail "wheelhil with no arguments printed no help"
[ -s "$root/usr/share/bash-completion/completions/wheelhil" ] || fail "no bash completion"

t0=$SECONDS
in_root sh -c "cd /tmp && wheelhil run /usr/share/wheelhil/scenarios/paper000_slip.yaml --out /tmp/run" \
  >"$debs/run.log" 2>&1 || { tail -20 "$debs/run.log" >&2; fail "the paper-000 scenario in the fresh root"; }
grep -q '"verdict": "pass"' "$root/tmp/run/report.json" || fail "verdict not pass"
log "paper000_slip in the fresh root: $(grep -E '^verdict|real time' "$debs/run.log" | tr '\n' ' ')($((SECONDS - t0)) s)"
echo "deb check: PASS ($(basename "$deb") on a fresh Debian $(cat "$root/etc/debian_version"))"
