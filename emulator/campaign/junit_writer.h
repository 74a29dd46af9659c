#pragma once
/// JUnit XML as GitLab, Jenkins and GitHub test reporters read it (the common "Jenkins JUnit"
/// schema): <testsuites tests failures errors time><testsuite name tests failures errors skipped
/// time><testcase classname name time><failure message type>text</failure></testcase>...
/// A case with `error` set is an <error> (the run could not be judged), with `failure` set a
/// <failure>. Thread-compatible.

#include <filesystem>
#include <string>
#include <vector>

namespace wheelhil::emulator::campaign {

struct JUnitCase {
  std::string classname;
  std::string name;
  double time_s = 0;
  std::string failure;  ///< non-empty: failed; first line is the message attribute
  std::string error;    ///< non-empty: errored (no verdict)
  std::string system_out;
};

struct JUnitSuite {
  std::string name;
  std::vector<JUnitCase> cases;
};

/// XML text of `suites` (UTF-8, XML-escaped, control characters dropped).
std::string JUnitXml(const std::vector<JUnitSuite>& suites, const std::string& name);
/// Writes JUnitXml atomically (temp file + rename). Throws std::runtime_error.
void WriteJUnit(const std::filesystem::path& file, const std::vector<JUnitSuite>& suites,
                const std::string& name);

}  // namespace wheelhil::emulator::campaign
