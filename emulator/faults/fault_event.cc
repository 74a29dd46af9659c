#include "emulator/faults/fault_event.h"

#include <algorithm>

#include <fmt/format.h>

namespace wheelhil::emulator {

namespace {

std::string JsonEscape(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (u < 0x20) {
      out += fmt::format("\\u{:04x}", u);
    } else {
      out += c;
    }
  }
  return out;
}

}  // namespace

std::vector<FaultEvent> FaultEventLog::SortedByTime() const {
  std::vector<FaultEvent> out = events_;
  std::stable_sort(out.begin(), out.end(),
                   [](const FaultEvent& a, const FaultEvent& b) { return a.t_ns < b.t_ns; });
  return out;
}

std::string FaultEventJson(const FaultEvent& e) {
  return fmt::format(
      R"({{"t_ns":{},"t_s":{:.9f},"category":"{}","kind":"{}","phase":"{}","target":"{}","detail":"{}"}})",
      e.t_ns, static_cast<double>(e.t_ns) * 1e-9, JsonEscape(e.category), JsonEscape(e.kind),
      JsonEscape(e.phase), JsonEscape(e.target), JsonEscape(e.detail));
}

namespace faults_internal {

void WindowPhase::Advance(std::int64_t t_ns, const FaultWindow& w, FaultEventLog* log,
                          std::string_view category, std::string_view kind, std::string_view target,
                          std::string_view detail) {
  if (!started_ && t_ns >= w.t0_ns) {
    started_ = true;
    if (log) {
      log->Record({w.t0_ns, std::string(category), std::string(kind), "start", std::string(target),
                   std::string(detail)});
    }
  }
  if (started_ && !ended_ && w.t1_ns != FaultWindow::kForever && t_ns >= w.t1_ns) {
    ended_ = true;
    if (log) {
      log->Record({w.t1_ns, std::string(category), std::string(kind), "end", std::string(target),
                   std::string(detail)});
    }
  }
}

}  // namespace faults_internal

}  // namespace wheelhil::emulator
