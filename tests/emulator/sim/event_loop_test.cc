// The run's discrete-event loop (emulator/sim/event_loop.h) with fake sources and a recording
// wait policy, and the bus hub (emulator/sim/bus_hub.h) with fake devices and a fake firmware
// that answers every SYNC: ordering at one instant, phases, failures, who hears which frame and
// when.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "emulator/sim/bus_hub.h"
#include "emulator/sim/event_loop.h"

namespace wheelhil::emulator::sim {
namespace {

// Fires every `period_ns` from `first_ns`, `count` times; logs "name@t".
class Periodic final : public EventSource {
 public:
  Periodic(std::string name, std::int64_t first_ns, std::int64_t period_ns, int count,
           std::vector<std::string>& log, bool stops_on_failure = true)
      : name_(std::move(name)), next_(first_ns), period_(period_ns), left_(count), log_(log),
        stops_(stops_on_failure) {}
  std::int64_t NextEventNs() const override { return left_ > 0 ? next_ : kNever; }
  void Fire(std::int64_t t_ns) override {
    log_.push_back(name_ + "@" + std::to_string(t_ns));
    next_ = t_ns + period_;
    --left_;
    if (on_fire) on_fire(t_ns);
  }
  bool StopsOnFailure() const override { return stops_; }
  std::function<void(std::int64_t)> on_fire;

 private:
  std::string name_;
  std::int64_t next_, period_;
  int left_;
  std::vector<std::string>& log_;
  bool stops_;
};

class RecordingWait final : public WaitPolicy {
 public:
  void StartPhase(std::int64_t t_ns) override { starts.push_back(t_ns); }
  void WaitFor(std::int64_t t_ns) override { waits.push_back(t_ns); }
  std::vector<std::int64_t> starts, waits;
};

TEST(EventLoop, AdvancesToTheEarliestInstantAndFiresInPhaseOrder) {
  RunContext run;
  RecordingWait wait;
  EventLoop loop(run, wait);
  std::vector<std::string> log;
  Periodic tick("tick", 10, 10, 4, log);  // 10 20 30 40
  Periodic sync("sync", 0, 20, 3, log);   // 0 20 40
  EXPECT_EQ(loop.Run({"p", {&tick, &sync}, nullptr}), 5u);
  EXPECT_THAT(log, ::testing::ElementsAre("sync@0", "tick@10", "tick@20", "sync@20", "tick@30",
                                          "tick@40", "sync@40"));
  // One wait per instant, never backwards.
  EXPECT_THAT(wait.waits, ::testing::ElementsAre(0, 10, 20, 30, 40));
  EXPECT_THAT(wait.starts, ::testing::ElementsAre(0));
}

TEST(EventLoop, DoneIsCheckedBeforeEveryInstant) {
  RunContext run;
  LockstepWait wait;
  EventLoop loop(run, wait);
  std::vector<std::string> log;
  Periodic tick("tick", 1, 1, 100, log);
  int fired = 0;
  tick.on_fire = [&](std::int64_t) { ++fired; };
  EXPECT_EQ(loop.Run({"p", {&tick}, [&] { return fired == 3; }}), 3u);
  EXPECT_EQ(log.size(), 3u);
}

TEST(EventLoop, AFailureStopsOnlyAtASourceThatStopsOnFailure) {
  RunContext run;
  LockstepWait wait;
  EventLoop loop(run, wait);
  std::vector<std::string> log;
  // Steps keep going after a failure until the next cycle boundary (as a run's motion phase).
  Periodic step("step", 1, 1, 10, log, /*stops_on_failure=*/false);
  Periodic cycle("cycle", 0, 4, 3, log);
  step.on_fire = [&](std::int64_t t) {
    if (t == 2) run.Fail("first");
    if (t == 3) run.Fail("second");  // the first failure is the cause; it stays
  };
  loop.Run({"p", {&step, &cycle}, nullptr});
  EXPECT_THAT(log,
              ::testing::ElementsAre("cycle@0", "step@1", "step@2", "step@3", "step@4"));
  EXPECT_EQ(run.failure, "first");
}

TEST(EventLoop, EndsWhenNoSourceHasAnInstantLeft) {
  RunContext run;
  LockstepWait wait;
  EventLoop loop(run, wait);
  std::vector<std::string> log;
  Periodic a("a", 5, 5, 2, log);
  EXPECT_EQ(loop.Run({"p", {&a}, nullptr}), 2u);
  EXPECT_EQ(loop.Run({"p", {&a}, nullptr}), 0u);
}

// A device that sends `id` at each multiple of `period_ns` and records what it hears.
class FakeDevice final : public Device {
 public:
  FakeDevice(std::string name, std::uint32_t id, std::int64_t period_ns)
      : name_(std::move(name)), id_(id), period_(period_ns), next_(period_ns) {}
  std::unique_ptr<Device> Clone() const override {
    return std::unique_ptr<Device>(new FakeDevice(*this));
  }
  const std::string& name() const override { return name_; }
  std::int64_t NextEventNs() const override { return next_; }
  void Poll(std::int64_t t_ns, const DeviceWorld&, DevicePort& port) override {
    std::vector<NodeFrame> out;
    for (; next_ <= t_ns; next_ += period_) {
      NodeFrame f;
      f.frame.id = id_;
      f.frame.len = 1;
      f.due_ns = next_;
      out.push_back(f);
    }
    port.Send(std::move(out), true);
  }
  void OnFrame(const bus::CanFrame& frame, std::int64_t t_ns, DevicePort&) override {
    heard.push_back({frame.id, t_ns});
  }
  void ArmFaults(DeviceFaults) override {}
  std::uint64_t suppressed_frames() const override { return 0; }
  std::vector<std::pair<std::uint32_t, std::int64_t>> heard;

 private:
  FakeDevice(const FakeDevice&) = default;

  std::string name_;
  std::uint32_t id_;
  std::int64_t period_, next_;
};

class RecordingObserver final : public BusObserver {
 public:
  void OnEmulatorFrame(const WireFrame& w, int device) override {
    seen.push_back({w.frame.id, device});
  }
  std::vector<std::pair<std::uint32_t, int>> seen;
};

TEST(BusHub, FramesReachEveryoneButTheirSenderAtTheirCompletionInstant) {
  RunContext run;
  std::vector<std::unique_ptr<Device>> devices;
  devices.push_back(std::make_unique<FakeDevice>("a", 0x181, 1'000'000));
  devices.push_back(std::make_unique<FakeDevice>("b", 0x182, 2'000'000));
  CanBusConfig bc;
  bc.bitrate_bps = 1'000'000;
  BusHub hub(bc, devices, run);
  const std::string log = (std::filesystem::temp_directory_path() / "bus_hub_test.log").string();
  hub.OpenLog(log, "ucan0");
  RecordingObserver observer;
  hub.SetObserver(&observer);
  // A fake firmware: answers every SYNC with 0x686 once it is on the wire.
  std::vector<bus::CanFrame> to_firmware;
  hub.SetFirmwareSend([&](const bus::CanFrame& f) {
    to_firmware.push_back(f);
    return true;
  });
  bus::CanFrame sync;
  sync.id = 0x080;
  hub.EnqueueSync(sync, 0);
  hub.AdvanceTo(500'000);
  ASSERT_EQ(to_firmware.size(), 1u);
  bus::CanFrame status;
  status.id = 0x686;
  status.len = 2;
  hub.EnqueueFromFirmware(status);
  DeviceWorld world;
  for (std::int64_t t = 1'000'000; t <= 2'000'000; t += 1'000'000) {
    for (std::size_t d = 0; d < devices.size(); ++d) devices[d]->Poll(t, world, hub.port(d));
    hub.AdvanceTo(t);
  }
  hub.AdvanceTo(3'000'000);
  hub.DrainToLog();
  hub.CloseLog();
  auto& a = static_cast<FakeDevice&>(*devices[0]);
  auto& b = static_cast<FakeDevice&>(*devices[1]);
  // a hears the SYNC, the firmware's status and b's frame, never its own.
  std::vector<std::uint32_t> a_ids, b_ids;
  for (const auto& [id, t] : a.heard) a_ids.push_back(id);
  for (const auto& [id, t] : b.heard) b_ids.push_back(id);
  EXPECT_THAT(a_ids, ::testing::ElementsAre(0x080, 0x686, 0x182));
  EXPECT_THAT(b_ids, ::testing::ElementsAre(0x080, 0x686, 0x181, 0x181));
  // A frame is heard when it completes: SYNC (0 data bytes) takes 44+ bits at 1 Mbit/s.
  EXPECT_GT(a.heard[0].second, 40'000);
  EXPECT_LT(a.heard[0].second, 60'000);
  // The firmware gets the SYNC and every device frame, not its own status.
  std::vector<std::uint32_t> fw_ids;
  for (const auto& f : to_firmware) fw_ids.push_back(f.id);
  // At 2 ms both devices' frames are ready: the lower id wins the arbitration.
  EXPECT_THAT(fw_ids, ::testing::ElementsAre(0x080, 0x181, 0x181, 0x182));
  // The observer tells the SYNC producer (-1) from the devices (their index).
  EXPECT_THAT(observer.seen,
              ::testing::ElementsAre(::testing::Pair(0x080u, -1), ::testing::Pair(0x181u, 0),
                                     ::testing::Pair(0x181u, 0), ::testing::Pair(0x182u, 1)));
  const auto m = hub.Metrics();
  EXPECT_EQ(m["frames"].get<std::uint64_t>(), 5u);
  EXPECT_EQ(m["firmware_frames"].get<std::uint64_t>(), 1u);
  std::filesystem::remove(log);
}

}  // namespace
}  // namespace wheelhil::emulator::sim
