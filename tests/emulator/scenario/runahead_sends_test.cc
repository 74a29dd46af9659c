// The firmware's sends a runahead window may foresee (SendPatterns): three sends with the same
// bytes at the same spacing, on the window's grid, in the order last sent; a send that did not
// come when due ends the pattern. And the ids no device reads (UnreadStandardIds).
#include "emulator/scenario/runahead_sends.h"

#include <gtest/gtest.h>

#include <memory>
#include <vector>

namespace wheelhil::emulator::scenario {
namespace {

constexpr std::int64_t kMs = 1'000'000;

bus::CanFrame Frame(std::uint32_t id, std::vector<std::uint8_t> data = {}) {
  bus::CanFrame f;
  f.id = id;
  f.len = static_cast<std::uint8_t>(data.size());
  for (std::size_t i = 0; i < data.size(); ++i) f.data[i] = data[i];
  return f;
}

std::vector<std::int64_t> Instants(const ForeseenSends& sends) {
  std::vector<std::int64_t> out;
  for (const auto& [t, f] : sends) out.push_back(t);
  return out;
}

TEST(SendPatterns, ThreeSendsAtOneSpacingWithTheSameBytesAreForeseen) {
  SendPatterns p;
  p.Note(Frame(0x080), 10 * kMs);
  p.Note(Frame(0x080), 12 * kMs);
  // Two sends make a spacing, not yet a pattern.
  EXPECT_TRUE(p.Foresee(12 * kMs, 20 * kMs, kMs, 256).empty());
  p.Note(Frame(0x080), 14 * kMs);
  const ForeseenSends f = p.Foresee(14 * kMs, 20 * kMs, kMs, 256);
  EXPECT_EQ(Instants(f), (std::vector<std::int64_t>{16 * kMs, 18 * kMs, 20 * kMs}));
  EXPECT_EQ(f.front().second, Frame(0x080));
  // At most `max`.
  EXPECT_EQ(p.Foresee(14 * kMs, 20 * kMs, kMs, 2).size(), 2u);
}

TEST(SendPatterns, OtherBytesOrAnotherSpacingStartAgain) {
  SendPatterns counter;  // a SYNC counter: never the same bytes
  for (int k = 0; k < 5; ++k) counter.Note(Frame(0x080, {static_cast<std::uint8_t>(k)}), k * kMs);
  EXPECT_TRUE(counter.Foresee(4 * kMs, 10 * kMs, kMs, 256).empty());
  SendPatterns jitter;
  for (std::int64_t t : {0 * kMs, 2 * kMs, 5 * kMs, 7 * kMs}) jitter.Note(Frame(0x080), t);
  EXPECT_TRUE(jitter.Foresee(7 * kMs, 20 * kMs, kMs, 256).empty());
}

TEST(SendPatterns, OffTheGridOrMissedIsNotForeseen) {
  SendPatterns off_grid;
  for (std::int64_t t : {0 * kMs, 3 * kMs / 2, 3 * kMs}) off_grid.Note(Frame(0x080), t);
  EXPECT_TRUE(off_grid.Foresee(3 * kMs, 10 * kMs, kMs, 256).empty());  // 1.5 ms spacing
  SendPatterns missed;
  for (std::int64_t t : {0 * kMs, 2 * kMs, 4 * kMs}) missed.Note(Frame(0x080), t);
  // Due at 6 ms, not sent by 7 ms: no longer expected, not even after 7 ms.
  EXPECT_TRUE(missed.Foresee(7 * kMs, 20 * kMs, kMs, 256).empty());
  EXPECT_TRUE(missed.Foresee(7 * kMs, 20 * kMs, kMs, 256).empty());
}

TEST(SendPatterns, FramesDueAtOneInstantComeInTheOrderLastSent) {
  SendPatterns p;
  for (std::int64_t t : {0 * kMs, 10 * kMs, 20 * kMs}) {
    p.Note(Frame(0x080), t);          // SYNC first
    p.Note(Frame(0x701, {0x05}), t);  // then its heartbeat, at the same instant
  }
  const ForeseenSends f = p.Foresee(20 * kMs, 30 * kMs, kMs, 256);
  ASSERT_EQ(f.size(), 2u);
  EXPECT_EQ(f[0].first, 30 * kMs);
  EXPECT_EQ(f[0].second.id, 0x080u);
  EXPECT_EQ(f[1].second.id, 0x701u);
}

class Reads final : public Device {
 public:
  explicit Reads(std::vector<std::uint32_t> ids) : ids_(std::move(ids)) {}
  std::unique_ptr<Device> Clone() const override { return std::make_unique<Reads>(ids_); }
  const std::string& name() const override { return name_; }
  std::int64_t NextEventNs() const override { return INT64_MAX; }
  void Poll(std::int64_t, const DeviceWorld&, DevicePort&) override {}
  void ArmFaults(DeviceFaults) override {}
  bool ReadsFrame(std::uint32_t id) const override {
    for (std::uint32_t i : ids_) {
      if (i == id) return true;
    }
    return false;
  }

 private:
  std::vector<std::uint32_t> ids_;
  std::string name_ = "reads";
};

TEST(UnreadStandardIds, AnIdIsUnreadWhenNoDeviceReadsIt) {
  std::vector<std::unique_ptr<Device>> devices;
  devices.push_back(std::make_unique<Reads>(std::vector<std::uint32_t>{0x000, 0x080}));
  devices.push_back(std::make_unique<Reads>(std::vector<std::uint32_t>{0x601}));
  const std::bitset<2048> unread = UnreadStandardIds(devices);
  EXPECT_FALSE(unread[0x000]);
  EXPECT_FALSE(unread[0x080]);
  EXPECT_FALSE(unread[0x601]);
  EXPECT_TRUE(unread[0x680]);
  EXPECT_EQ(unread.count(), 2048u - 3u);
}

}  // namespace
}  // namespace wheelhil::emulator::scenario
