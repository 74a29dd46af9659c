#include "emulator/scenario/runahead_sends.h"

#include <algorithm>
#include <tuple>

namespace wheelhil::emulator::scenario {

void SendPatterns::Note(const bus::CanFrame& frame, std::int64_t t_ns) {
  const std::uint32_t key =
      frame.id | (frame.extended ? 1u << 31 : 0u) | (frame.rtr ? 1u << 30 : 0u);
  Pattern& p = patterns_[key];
  const bool same = p.last_ns >= 0 && p.frame == frame && t_ns > p.last_ns;
  if (same && p.period_ns == t_ns - p.last_ns) {
    ++p.repeats;
  } else if (same) {
    p.period_ns = t_ns - p.last_ns;
    p.repeats = 1;
  } else {
    p.frame = frame;
    p.period_ns = 0;
    p.repeats = 0;
  }
  p.last_ns = t_ns;
  p.seq = ++seq_;
}

ForeseenSends SendPatterns::Foresee(std::int64_t now_ns, std::int64_t until_ns,
                                    std::int64_t step_ns, std::size_t max) {
  std::vector<std::tuple<std::int64_t, std::uint64_t, const bus::CanFrame*>> due;
  for (auto& [key, p] : patterns_) {
    if (p.repeats < kRepeats) continue;
    if (p.last_ns + p.period_ns <= now_ns) {
      p.repeats = 0;  // it did not come when due
      continue;
    }
    if (step_ns <= 0 || p.period_ns % step_ns != 0 || (p.last_ns - now_ns) % step_ns != 0) {
      continue;  // off the grid the firmware's library moves its clock on
    }
    for (std::int64_t t = p.last_ns + p.period_ns; t <= until_ns && due.size() < 4 * max;
         t += p.period_ns) {
      due.emplace_back(t, p.seq, &p.frame);
    }
  }
  std::sort(due.begin(), due.end(), [](const auto& a, const auto& b) {
    return std::tie(std::get<0>(a), std::get<1>(a)) < std::tie(std::get<0>(b), std::get<1>(b));
  });
  ForeseenSends out;
  for (const auto& [t, seq, frame] : due) {
    if (out.size() == max) break;
    out.emplace_back(t, *frame);
  }
  return out;
}

std::bitset<2048> UnreadStandardIds(const std::vector<std::unique_ptr<Device>>& devices) {
  std::bitset<2048> unread;
  for (std::uint32_t id = 0; id < 2048; ++id) {
    unread[id] = std::none_of(devices.begin(), devices.end(),
                              [id](const auto& d) { return d->ReadsFrame(id); });
  }
  return unread;
}

}  // namespace wheelhil::emulator::scenario
