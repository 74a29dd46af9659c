#pragma once
/// The private runtime directory of the userspace CAN bus: where the broker's socket
/// (`ucan.sock`) and lock file live. Chosen as `$WHEELHIL_UCAN_DIR` if set, else
/// `$XDG_RUNTIME_DIR/wheelhil`, else `/tmp/wheelhil-<uid>`. It must be a real directory (not a
/// symlink) owned by the effective user with mode 0700; anything else is refused, so another
/// user cannot plant a fake broker.
///
/// Used by the broker and by the interposition library (loaded into arbitrary programs):
/// no global objects, no exceptions escape; thread-safe (reads the environment only).

#include <string>
#include <system_error>
#include <utility>
#include <vector>

namespace wheelhil::bus {

/// The directory the environment selects (not created, not checked).
std::string ResolveUcanRuntimeDir();

/// Checks that `dir` is a directory, not a symlink, owned by geteuid(), mode exactly 0700.
/// Errors: no_such_file_or_directory, not_a_directory, permission_denied (owner or mode).
std::error_code VerifyUcanRuntimeDir(const std::string& dir) noexcept;

/// Creates `dir` (one level, mode 0700) when missing, then verifies it.
std::error_code EnsureUcanRuntimeDir(const std::string& dir) noexcept;

/// `<dir>/ucan.sock`.
std::string UcanSocketPath(const std::string& dir);

/// Where temporary runtime directories go: $TMPDIR, else /tmp.
std::string UcanTempRoot();

/// Creates a fresh private runtime directory (mkdtemp, mode 0700) under $TMPDIR or /tmp, for
/// one run's private buses (e.g. UcanBrokerOptions{.runtime_dir = ..., .remove_runtime_dir =
/// true}). Throws std::system_error when it cannot.
std::string CreateTempUcanRuntimeDir(const std::string& prefix = "wheelhil-ucan-");

/// Environment entries that put a child program on the buses of `runtime_dir`:
/// LD_PRELOAD = `preload_library`[:the current $LD_PRELOAD], WHEELHIL_UCAN_DIR = `runtime_dir`,
/// and ASAN_OPTIONS = the current value + `verify_asan_link_order=0`, because an
/// AddressSanitizer-built child otherwise refuses to start when a preload precedes libasan.
std::vector<std::pair<std::string, std::string>> UcanChildEnvironment(
    const std::string& preload_library, const std::string& runtime_dir);

}  // namespace wheelhil::bus
