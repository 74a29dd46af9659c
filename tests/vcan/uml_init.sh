#!/bin/bash
# PID 1 of the user-mode-linux guest booted by tests/vcan/uml_run.sh. Do not run it by hand.
# Runs under bash, not busybox sh: busybox re-executes /proc/self/exe, which before /proc is
# mounted resolves to the host's UML binary. The root file system is the host's `/`, read-only
# over hostfs. The kernel hands WHEELHIL_UML_WORK (a host directory) over as an environment
# variable; everything else comes from files in it:
#   modules  .ko paths to insmod, one a line, in load order ('?' prefix: optional)
#   cwd      working directory of the command      env  NAME=VALUE list, NUL-separated
#   cmd      argv of the command, NUL-separated    rw   extra directories to mount writable
# and it writes back: init.log (this script's trace), stdout, stderr, rc (the exit code) or
# skip (a reason, when the guest lacks what the tests need).
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
W="${WHEELHIL_UML_WORK:-}"

# Process starts are slow inside UML (~0.1 s each), so this script uses bash builtins wherever
# it can and starts only mount, insmod, ip and the command itself.
up() { local u _; read -r u _ < /proc/uptime; echo "$u"; }

power_off() {
  sync
  echo o > /proc/sysrq-trigger
  sleep 30
}
trap power_off EXIT

mount -t proc proc /proc
mount -t sysfs sysfs /sys
mount -t tmpfs -o mode=1777 tmpfs /tmp
mount -t tmpfs -o mode=755 tmpfs /run
if [ -z "$W" ]; then
  echo "uml_init: WHEELHIL_UML_WORK not set on the kernel command line" > /dev/console
  exit 1
fi
[ -d "$W" ] || mkdir -p "$W"
if ! mount -t hostfs hostfs "$W" -o "$W"; then
  echo "uml_init: cannot mount host directory $W" > /dev/console
  exit 1
fi
exec > "$W/init.log" 2>&1
read -r kernel < /proc/sys/kernel/osrelease
echo "uml_init: kernel $kernel, init started at $(up) s"

fail() { echo "uml_init: $*"; exit 1; }
skip() { echo "$*" > "$W/skip"; echo "uml_init: SKIP: $*"; exit 0; }

# Writable host directories: the command's cwd and anything asked for with --rw.
read -r cwd < "$W/cwd"
mapfile -t rw < "$W/rw"
# Parents before children, so a directory mounted inside another stays visible.
# (no process substitution: the guest has no /dev/fd)
sorted="$(printf '%s\n' "$cwd" "${rw[@]}" | awk 'NF { print length($0) "\t" $0 }' | sort -n -u \
  | cut -f2-)"
mapfile -t dirs <<< "$sorted"
for dir in "${dirs[@]}"; do
  [ -n "$dir" ] || continue
  [ -d "$dir" ] || mkdir -p "$dir"
  mount -t hostfs hostfs "$dir" -o "$dir" || fail "cannot mount $dir writable"
done
mkdir /dev/shm && mount -t tmpfs -o mode=1777 tmpfs /dev/shm

insmod_cmd=(insmod)
command -v busybox > /dev/null && insmod_cmd=(busybox insmod)
mapfile -t modules < "$W/modules"
for ko in "${modules[@]}"; do
  optional=0
  if [ "${ko#\?}" != "$ko" ]; then optional=1; ko="${ko#\?}"; fi
  [ -n "$ko" ] || continue
  if ! "${insmod_cmd[@]}" "$ko"; then
    [ "$optional" = 1 ] && continue
    fail "insmod $ko failed"
  fi
done
[ -e /proc/net/can ] || skip "no AF_CAN in the UML kernel after loading its modules"
echo "uml_init: modules loaded at $(up) s"

# One iproute2 `ip` process for all of it (every process start is slow inside UML); busybox's
# ip has no -batch, so it gets one call per step.
printf 'link add dev %s type vcan\nlink set %s up\n' vcan0 vcan0 vcan1 vcan1 > /run/vcan.ip
if ! ip -batch /run/vcan.ip; then
  while read -r -a step; do
    ip "${step[@]}" || busybox ip "${step[@]}" || skip "cannot run 'ip ${step[*]}' in the guest"
  done < /run/vcan.ip
fi
echo "uml_init: vcan ready at $(up) s"

mapfile -d '' -t envs < "$W/env"
mapfile -d '' -t argv < "$W/cmd"
# The command runs as root in here; give it the sbin directories (ip, tc) an ordinary user's
# PATH may lack.
for i in "${!envs[@]}"; do
  case "${envs[$i]}" in
    PATH=*) [[ ":${envs[$i]#PATH=}:" == *:/usr/sbin:* ]] || envs[i]="${envs[$i]}:/usr/sbin:/sbin" ;;
  esac
done
cd "$cwd" || fail "cannot cd to $cwd"

env -i "${envs[@]}" WHEELHIL_VCAN=vcan0 WHEELHIL_VCAN2=vcan1 WHEELHIL_UML=1 \
  "${argv[@]}" < /dev/null > "$W/stdout" 2> "$W/stderr"
rc=$?

echo "uml_init: command exited with $rc at $(up) s"
echo "$rc" > "$W/rc"
