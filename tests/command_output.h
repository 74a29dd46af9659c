#pragma once
// Shared by the tests that check wheelhil's files with other programs (can-utils, python-can,
// node, gdb): running a shell command for its output, and finding a Python with python-can.

#include <cstdio>
#include <cstdlib>
#include <string>

namespace wheelhil::test_support {

/// What `command` (run by the shell) wrote to stdout; `*status` (if given): pclose's status.
inline std::string CommandOutput(const std::string& command, int* status = nullptr) {
  std::string out;
  FILE* p = ::popen(command.c_str(), "r");
  if (p == nullptr) {
    if (status != nullptr) *status = -1;
    return out;
  }
  char buf[4096];
  while (const std::size_t n = std::fread(buf, 1, sizeof buf, p)) out.append(buf, n);
  const int s = ::pclose(p);
  if (status != nullptr) *status = s;
  return out;
}

/// Debian's python3 (/usr/bin/python3: python3 on PATH may be another install) or python3, the
/// first that imports python-can; empty when none does.
inline std::string PythonWithCan() {
  for (const char* py : {"/usr/bin/python3", "python3"}) {
    if (std::system((std::string(py) + " -c 'import can' >/dev/null 2>&1").c_str()) == 0) {
      return py;
    }
  }
  return "";
}

}  // namespace wheelhil::test_support
