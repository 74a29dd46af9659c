#!/usr/bin/env bash
# An installed wheelhil works on its own: installs the build tree into a temporary prefix,
# moves the tree elsewhere (the programs find their files relative to themselves), then, from a
# directory outside the source tree and with no WHEELHIL_* variable set,
#   1. runs an installed scenario (the reference firmware on a private userspace bus) and
#      requires its verdict "pass";
#   2. runs a can-utils program on an installed ucan bus through `wheelhil exec`;
#   3. builds and runs a small CMake project that finds the package (find_package(wheelhil))
#      and links wheelhil::bus, decoding a frame with an installed DBC file.
# Usage: install_tree_test.sh BUILD_DIR [EXTRA_CXX_FLAGS]   (the flags: a sanitizer build's)
set -euo pipefail
build="$1"
extra_flags="${2:-}"
tmp="$(mktemp -d /tmp/wheelhil-install-test.XXXXXX)"
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*" >&2; exit 1; }

cmake --install "$build" --prefix "$tmp/staged" >"$tmp/install.log" 2>&1 ||
  { cat "$tmp/install.log" >&2; fail "cmake --install"; }
mv "$tmp/staged" "$tmp/prefix"
p="$tmp/prefix"
for f in bin/wheelhil bin/wheelhil-fw share/wheelhil/dbc/wheelhil_fw.dbc \
         share/wheelhil/scenarios/paper000_slip.yaml share/wheelhil/meshes/ramp.obj \
         share/doc/wheelhil/README.md share/bash-completion/completions/wheelhil; do
  [ -e "$p/$f" ] || fail "not installed: $f"
done
preload="$(find "$p" -name libwheelhil_ucan.so)"
[ -n "$preload" ] || fail "libwheelhil_ucan.so not installed"
[ -e "$(dirname "$preload")/libwheelhil_vtime.so" ] || fail "libwheelhil_vtime.so not beside $preload"
config="$(find "$p" -name wheelhilConfig.cmake)"
[ -n "$config" ] || fail "wheelhilConfig.cmake not installed"

cd "$tmp"
clean_env=(env -u WHEELHIL_DBC_DIR -u WHEELHIL_UCAN_LIB -u WHEELHIL_VTIME_LIB -u WHEELHIL_UCAN_DIR
           -u LD_PRELOAD)

# 1. A scenario from the installed examples.
"${clean_env[@]}" "$p/bin/wheelhil" run "$p/share/wheelhil/scenarios/smoke/paper000_slip_short.yaml" \
  --out "$tmp/run" --quiet >"$tmp/run.log" 2>&1 || { cat "$tmp/run.log" >&2; fail "wheelhil run"; }
grep -q '"verdict": "pass"' "$tmp/run/report.json" ||
  { grep -m3 '"verdict"\|"failure"' "$tmp/run/report.json" >&2; fail "the installed run did not pass"; }
[ -s "$tmp/run/can.log" ] || fail "no can.log"

# 1b. A project from `wheelhil new` (the installed templates, a URDF robot, the installed
#     schemas named at the top of each file) runs and passes.
"${clean_env[@]}" "$p/bin/wheelhil" new "$tmp/proj" \
  --urdf "$p/share/wheelhil/scenarios/platforms/urdf/diff2.urdf" >"$tmp/new.log" 2>&1 ||
  { cat "$tmp/new.log" >&2; fail "wheelhil new"; }
grep -q "^# yaml-language-server: \$schema=.*/share/wheelhil/schemas/scenario.schema.json$" \
  "$tmp/proj/scenario.yaml" || fail "the new project's scenario names no installed schema"
(cd "$tmp/proj" && "${clean_env[@]}" "$p/bin/wheelhil" run scenario.yaml --out run --quiet \
  >"$tmp/proj.log" 2>&1) || { cat "$tmp/proj.log" >&2; fail "run of the new project"; }
grep -q '"verdict": "pass"' "$tmp/proj/run/report.json" || fail "the new project's run did not pass"

# 2. A third-party SocketCAN program on an installed userspace bus.
if command -v cansend >/dev/null; then
  "${clean_env[@]}" WHEELHIL_UCAN_DIR="$tmp/ucan" "$p/bin/wheelhil" exec --bus ucan7 -- \
    cansend ucan7 123#DEADBEEF >"$tmp/exec.log" 2>&1 || { cat "$tmp/exec.log" >&2; fail "wheelhil exec cansend"; }
  "${clean_env[@]}" WHEELHIL_UCAN_DIR="$tmp/ucan" "$p/bin/wheelhil" bus list | grep -q '^ucan7 ' ||
    fail "wheelhil bus list does not show ucan7"
  "${clean_env[@]}" WHEELHIL_UCAN_DIR="$tmp/ucan" "$p/bin/wheelhil" bus down ucan7 >/dev/null
fi

# 3. A user's own tool against the installed CMake package.
mkdir -p "$tmp/consumer"
cat >"$tmp/consumer/CMakeLists.txt" <<'CMAKE'
cmake_minimum_required(VERSION 3.25)
project(consumer CXX)
set(CMAKE_CXX_STANDARD 20)
find_package(wheelhil 0.1 REQUIRED)
add_executable(decode_pose main.cc)
target_link_libraries(decode_pose PRIVATE wheelhil::bus)
target_compile_definitions(decode_pose PRIVATE DBC_FILE="${wheelhil_DATA_DIR}/dbc/wheelhil_fw.dbc")
CMAKE
cat >"$tmp/consumer/main.cc" <<'CXX'
#include <cstdio>
#include "bus/dbc.h"
#include "bus/dbc_codec.h"
int main() {
  using namespace wheelhil::bus;
  const DbcDatabase db = DbcDatabase::LoadFile(DBC_FILE);
  const DbcMessage* pose = db.FindMessage("FW_Pose");
  if (pose == nullptr) return 3;
  const CanFrame f = EncodeMessage(*pose, {{"Pose_X", 1.25}, {"Pose_Y", -0.5}});
  const SignalValues v = DecodeMessage(*pose, f);
  std::printf("%03X %.4f %.4f\n", f.id, v.at("Pose_X"), v.at("Pose_Y"));
  return 0;
}
CXX
cmake -S "$tmp/consumer" -B "$tmp/consumer/build" -DCMAKE_PREFIX_PATH="$p" \
  -DCMAKE_CXX_FLAGS="$extra_flags" -DCMAKE_EXE_LINKER_FLAGS="$extra_flags" \
  >"$tmp/consumer.log" 2>&1 || { cat "$tmp/consumer.log" >&2; fail "configuring a find_package(wheelhil) project"; }
cmake --build "$tmp/consumer/build" >>"$tmp/consumer.log" 2>&1 ||
  { cat "$tmp/consumer.log" >&2; fail "building against wheelhil::bus"; }
out="$("$tmp/consumer/build/decode_pose")"
[ "$out" = "680 1.2500 -0.5000" ] || fail "the consumer decoded '$out', expected '680 1.2500 -0.5000'"
echo "installed tree: run passed, a new project ran, exec worked, find_package(wheelhil) consumer: $out"
