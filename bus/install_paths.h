#pragma once
/// Where wheelhil's programs find their own files, in a build tree or in an install.
/// A build tree: <build>/bin/<program>, <build>/lib/libwheelhil_*.so, the data in the source tree
/// (<build>/../bus/dbc, a build directory directly under the source root, as ./hil makes them).
/// An install (CMake install rules, the Debian package): <bindir>/<program>,
/// <libdir>/wheelhil/libwheelhil_*.so, <datadir>/wheelhil/{dbc,scenarios,meshes}, found relative
/// to the program's own directory, so an installed tree can be moved to any prefix.
/// Environment overrides ($WHEELHIL_DBC_DIR, $WHEELHIL_UCAN_LIB) are the callers' business.
/// Thread-safe (reads /proc/self/exe and the file system only).

#include <string>

namespace wheelhil::bus {

/// Directory of the running executable (/proc/self/exe), "." if it cannot be read.
std::string RunningExecutableDir();

/// <datadir>/wheelhil relative to an installed program's directory, e.g. "../share/wheelhil".
std::string InstalledDataDirFromBin();

/// The directory holding wheelhil_fw.dbc: <exe_dir>/../../bus/dbc (a build tree), else
/// <exe_dir>/<bin-to-data>/dbc (an install); canonical. Empty when neither has it.
std::string FindShippedDbcDir(const std::string& exe_dir);

/// The directory holding the shipped scenarios/ (and docs/schemas or schemas/): the source
/// root above a build directory (<exe_dir>/../..), else <exe_dir>/<bin-to-data> (an install);
/// canonical. Empty when neither has scenarios/platforms/diff2.yaml.
std::string FindShippedDataRoot(const std::string& exe_dir);

/// A preload library (`file`, e.g. "libwheelhil_ucan.so"): <exe_dir>/../lib/<file> (a build
/// tree), else <exe_dir>/<bin-to-preload>/<file> (an install). When neither exists, the install
/// path, so that the caller's "not found" names where it should be.
std::string FindPreloadLibrary(const std::string& exe_dir, const std::string& file);

}  // namespace wheelhil::bus
