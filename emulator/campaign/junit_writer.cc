#include "emulator/campaign/junit_writer.h"

#include <fmt/format.h>

#include <fstream>
#include <stdexcept>

#include "emulator/xml_escape.h"

namespace wheelhil::emulator::campaign {
namespace {

std::string FirstLine(const std::string& s) {
  const auto nl = s.find('\n');
  std::string line = nl == std::string::npos ? s : s.substr(0, nl);
  if (line.size() > 500) {
    // Cut before a character, not inside one (a continuation byte is 10xxxxxx).
    std::size_t cut = 500;
    while (cut > 0 && (static_cast<unsigned char>(line[cut]) & 0xC0) == 0x80) --cut;
    line = line.substr(0, cut) + "...";
  }
  return line;
}

}  // namespace

std::string JUnitXml(const std::vector<JUnitSuite>& suites, const std::string& name) {
  std::size_t tests = 0, failures = 0, errors = 0;
  double time_s = 0;
  std::string body;
  for (const auto& suite : suites) {
    std::size_t f = 0, e = 0;
    double t = 0;
    std::string cases;
    for (const auto& c : suite.cases) {
      t += c.time_s;
      cases += fmt::format("    <testcase classname=\"{}\" name=\"{}\" time=\"{:.3f}\"",
                           EscapeXml(c.classname), EscapeXml(c.name), c.time_s);
      if (c.failure.empty() && c.error.empty() && c.system_out.empty()) {
        cases += "/>\n";
        continue;
      }
      cases += ">\n";
      if (!c.error.empty()) {
        ++e;
        cases += fmt::format("      <error message=\"{}\" type=\"error\">{}</error>\n",
                             EscapeXml(FirstLine(c.error)), EscapeXml(c.error));
      } else if (!c.failure.empty()) {
        ++f;
        cases += fmt::format("      <failure message=\"{}\" type=\"failure\">{}</failure>\n",
                             EscapeXml(FirstLine(c.failure)), EscapeXml(c.failure));
      }
      if (!c.system_out.empty()) {
        cases += fmt::format("      <system-out>{}</system-out>\n", EscapeXml(c.system_out));
      }
      cases += "    </testcase>\n";
    }
    body += fmt::format(
        "  <testsuite name=\"{}\" tests=\"{}\" failures=\"{}\" errors=\"{}\" skipped=\"0\" "
        "time=\"{:.3f}\">\n{}  </testsuite>\n",
        EscapeXml(suite.name), suite.cases.size(), f, e, t, cases);
    tests += suite.cases.size();
    failures += f;
    errors += e;
    time_s += t;
  }
  return fmt::format(
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<testsuites name=\"{}\" tests=\"{}\" failures=\"{}\" errors=\"{}\" time=\"{:.3f}\">\n"
      "{}</testsuites>\n",
      EscapeXml(name), tests, failures, errors, time_s, body);
}

void WriteJUnit(const std::filesystem::path& file, const std::vector<JUnitSuite>& suites,
                const std::string& name) {
  if (file.has_parent_path()) std::filesystem::create_directories(file.parent_path());
  const auto tmp = file.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << JUnitXml(suites, name);
    if (!out) throw std::runtime_error(fmt::format("cannot write {}", tmp));
  }
  std::filesystem::rename(tmp, file);
}

}  // namespace wheelhil::emulator::campaign
