#!/usr/bin/env bash
# Runs COMMAND inside a user-mode-linux (UML) guest that has a real kernel SocketCAN stack with
# two virtual CAN interfaces, vcan0 and vcan1, both up. Needs no root: UML is an ordinary
# process. The guest sees the host's file system (read-only, except the current directory and
# --rw directories), the caller's environment plus WHEELHIL_VCAN=vcan0 WHEELHIL_VCAN2=vcan1
# WHEELHIL_UML=1, and the current directory. COMMAND runs as root inside the guest (so it may
# `ip link set vcan1 down`); files it writes belong to the host user running this script.
# COMMAND's stdout/stderr are printed after it ends; its exit code is this script's exit code.
#
# usage: tests/vcan/uml_run.sh [--timeout SEC] [--mem SIZE] [--rw DIR]... [--keep] [--] COMMAND...
#   --timeout SEC  kill the guest after SEC seconds (default 120; exit code 124)
#   --mem SIZE     guest memory (default 256M)
#   --rw DIR       also make host directory DIR writable inside the guest
#   --keep         keep the work directory (console log, init log) and print its path
# Exit codes: COMMAND's; 77 with "SKIP: <reason>" when UML, busybox/insmod, ip or the CAN
# modules are missing (CTest SKIP_RETURN_CODE); 1 when the guest failed to boot or set up.
# Environment: WHEELHIL_UML_LINUX (UML binary, default /usr/bin/linux.uml or `linux`),
# WHEELHIL_UML_MODULES (module tree, default /usr/lib/uml/modules/<version>).
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
INIT="$HERE/uml_init.sh"
timeout_s=120
mem=256M
keep=0
rw=()

skip() { echo "SKIP: $*"; exit 77; }
die() { echo "uml_run.sh: $*" >&2; exit 1; }

while [ $# -gt 0 ]; do
  case "$1" in
    --timeout) timeout_s="$2"; shift 2 ;;
    --mem) mem="$2"; shift 2 ;;
    --rw) rw+=("$(cd "$2" && pwd)"); shift 2 ;;
    --keep) keep=1; shift ;;
    --) shift; break ;;
    -h|--help) sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    -*) die "unknown option $1 (see --help)" ;;
    *) break ;;
  esac
done
[ $# -gt 0 ] || die "no command given (usage: uml_run.sh [options] [--] COMMAND...)"

# --- What the guest needs; anything missing is a SKIP, not a failure. ---
uml="${WHEELHIL_UML_LINUX:-}"
if [ -z "$uml" ]; then
  if [ -x /usr/bin/linux.uml ]; then uml=/usr/bin/linux.uml
  else uml="$(command -v linux || true)"; fi
fi
if [ -z "$uml" ] || [ ! -x "$uml" ]; then
  skip "user-mode-linux not installed (apt-get install user-mode-linux)"
fi
kver="$("$uml" --version 2>/dev/null | head -n1 | tr -d '[:space:]')"
[ -n "$kver" ] || skip "$uml --version printed no kernel version (not a UML kernel?)"
moddir="${WHEELHIL_UML_MODULES:-/usr/lib/uml/modules/$kver}"
[ -f "$moddir/modules.dep" ] || skip "no UML kernel modules for $kver in $moddir"
if ! command -v busybox > /dev/null && ! command -v insmod > /dev/null; then
  skip "neither busybox nor insmod found (apt-get install busybox-static)"
fi
command -v ip > /dev/null || command -v busybox > /dev/null || skip "no ip command (iproute2)"
[ -x "$INIT" ] || die "$INIT missing or not executable"
case "$INIT" in *[[:space:],]*) skip "path $INIT contains spaces or commas (kernel command line)" ;; esac

work="$(mktemp -d "${TMPDIR:-/tmp}/wheelhil-uml.XXXXXX")"
# shellcheck disable=SC2317  # called from the EXIT trap
cleanup() { if [ "$keep" = 1 ]; then echo "uml_run.sh: kept $work" >&2; else rm -rf "$work"; fi; }
trap cleanup EXIT
case "$work" in *[[:space:],]*) skip "work directory $work contains spaces or commas" ;; esac

# Module list in load order, dependencies first (modules.dep: "path: dep1 dep2", the deps
# listed so that the last one loads first). Compressed modules are unpacked for busybox insmod.
declare -A loaded=()
: > "$work/modules"
add_module() {  # add_module NAME [optional]
  local name="$1" optional="${2:-}" line path deps dep
  line="$(grep -E "(^|/)${name}\.ko(\.xz|\.zst|\.gz)?:" "$moddir/modules.dep" | head -n1 || true)"
  if [ -z "$line" ]; then
    [ -n "$optional" ] && return 0
    skip "kernel module $name not in $moddir (UML kernel built without it?)"
  fi
  path="${line%%:*}"
  [ -n "${loaded[$path]:-}" ] && return 0
  loaded[$path]=1
  deps="${line#*:}"
  local -a dep_list
  read -ra dep_list <<< "$deps"
  local i
  for ((i = ${#dep_list[@]} - 1; i >= 0; i--)); do
    dep="$(basename "${dep_list[$i]}")"; dep="${dep%%.ko*}"
    add_module "$dep" "$optional"
  done
  local src="$moddir/$path" ko unpack=()
  case "$path" in
    *.ko) ko="$src" ;;
    *.ko.xz) ko="$work/$(basename "$path" .xz)"; unpack=(xz -dc) ;;
    *.ko.zst) ko="$work/$(basename "$path" .zst)"; unpack=(zstd -qdc) ;;
    *.ko.gz) ko="$work/$(basename "$path" .gz)"; unpack=(gzip -dc) ;;
  esac
  if [ ${#unpack[@]} -gt 0 ] && ! "${unpack[@]}" "$src" > "$ko" 2> /dev/null; then
    rm -f "$ko"
    [ -n "$optional" ] && return 0
    skip "cannot unpack $src (${unpack[0]} missing?)"
  fi
  if [ ! -f "$ko" ]; then
    [ -n "$optional" ] && return 0
    skip "module file $ko missing"
  fi
  echo "${optional:+?}$ko" >> "$work/modules"
}
for m in can can-raw can-dev vcan; do add_module "$m"; done
# Optional extras (each insmod costs 0.1-0.2 s of boot): the broadcast manager, and the netem
# and tbf queueing disciplines so tests can fill a device queue (ENOBUFS) or hold send-buffer
# memory (EAGAIN).
for m in can-bcm sch_netem sch_tbf; do add_module "$m" optional; done

# The guest mounts a fresh tmpfs over /tmp, so a checkout or build tree under /tmp (as in CI
# clones) would vanish there: mount the source tree and the command's directory from the host.
rw+=("$(cd "$(dirname "$0")/../.." && pwd -P)")
if [ "${1#/}" != "$1" ] && [ -d "$(dirname "$1")" ]; then rw+=("$(cd "$(dirname "$1")" && pwd -P)"); fi
pwd -P > "$work/cwd"
printf '%s\n' "${rw[@]+"${rw[@]}"}" > "$work/rw"
env -0 | grep -zvE '^(PWD|OLDPWD|SHLVL|_)=' > "$work/env" || true
printf '%s\0' "$@" > "$work/cmd"

mkdir -p "$work/uml"
start_ns="$(date +%s%N)"
set +e
# UML backs guest memory with a file under TMPDIR; keep it in RAM (/dev/shm) when possible.
shm="${TMPDIR:-/tmp}"
[ -d /dev/shm ] && [ -w /dev/shm ] && shm=/dev/shm
TMPDIR="$shm" timeout --kill-after=5 "$timeout_s" "$uml" \
  mem="$mem" uml_dir="$work/uml" umid=wheelhil "root=/dev/root" rootfstype=hostfs \
  rootflags=/ ro init="$INIT" WHEELHIL_UML_WORK="$work" con=null con0=null,fd:1 \
  < /dev/null > "$work/console.log" 2>&1
uml_rc=$?
set -e
elapsed_ms=$(( ($(date +%s%N) - start_ns) / 1000000 ))

if [ -f "$work/skip" ]; then skip "$(cat "$work/skip")"; fi
# UML runs its guest processes under ptrace; a sandbox that forbids ptrace (seccomp, Yama
# ptrace_scope 3) stops it before the kernel boots. An environment limit, not a test failure.
if [ ! -f "$work/init.log" ] && grep -qE 'check_ptrace|ptrace failed|PTRACE_[A-Z]+ failed' \
    "$work/console.log" 2> /dev/null; then
  grep -m3 -E 'ptrace' "$work/console.log" >&2 || true
  skip "user-mode-linux cannot use ptrace in this environment (container seccomp policy or kernel.yama.ptrace_scope)"
fi
# Some hosts boot the UML kernel but kill its first user-space process with SIGSEGV before it
# runs a single command (seen on a 6.18 host kernel: the fault comes from UML restoring the
# process's FPU registers, even for a static busybox as init). No guest program can run there:
# an environment limit, not a test failure. A broken init script fails differently (it writes
# init.log first, or exits with a status, not signal 11).
if [ ! -f "$work/init.log" ] && grep -q 'Attempted to kill init! exitcode=0x0000000b' \
    "$work/console.log" 2> /dev/null; then
  grep -m1 -E 'Kernel panic' "$work/console.log" >&2 || true
  skip "user-mode-linux cannot run user space on this host (kernel $(uname -r)): its init died with SIGSEGV before its first command"
fi
if [ -f "$work/rc" ]; then
  # The Debian UML kernel has 3-level page tables: a 39-bit (512 GiB) user address space, too
  # small for the shadow memory of AddressSanitizer / ThreadSanitizer binaries (`./hil test
  # --asan`). That is a limit of the guest, not a test failure.
  if [ "$(cat "$work/rc")" != 0 ] && grep -qE \
      'ASan shadow was supposed to be located|Shadow memory range interleaves|ThreadSanitizer: unexpected memory mapping' \
      "$work/stderr" 2> /dev/null; then
    head -n 3 "$work/stderr" >&2
    skip "sanitizer builds cannot run in the UML guest (39-bit address space, too small for the shadow memory)"
  fi
  [ -f "$work/stdout" ] && cat "$work/stdout"
  [ -f "$work/stderr" ] && cat "$work/stderr" >&2
  echo "uml_run.sh: guest ran for ${elapsed_ms} ms; $(grep -m1 'vcan ready' "$work/init.log" || true)" >&2
  exit "$(cat "$work/rc")"
fi
{
  if [ "$uml_rc" = 124 ] || [ "$uml_rc" = 137 ]; then
    echo "uml_run.sh: the UML guest timed out after ${timeout_s} s"
  else
    echo "uml_run.sh: the UML guest ended (status $uml_rc) without reporting an exit code"
  fi
  [ "$keep" = 1 ] || echo "(rerun with --keep to keep $work: console.log, init.log)"
  echo "--- last lines of the UML console ---"
  tail -n 25 "$work/console.log"
  if [ -f "$work/init.log" ]; then echo "--- init log ---"; cat "$work/init.log"; fi
  [ -f "$work/stdout" ] && { echo "--- command stdout ---"; tail -n 50 "$work/stdout"; }
  [ -f "$work/stderr" ] && { echo "--- command stderr ---"; tail -n 50 "$work/stderr"; }
} >&2
[ "$uml_rc" = 124 ] || [ "$uml_rc" = 137 ] && exit 124
exit 1
