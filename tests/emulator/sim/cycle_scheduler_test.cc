// The run's step and SYNC sources (emulator/sim/cycle_scheduler.h) on fake stages and a fake
// firmware gate: the order of the stages in a cycle, the firmware drained after every step,
// the last cycle, and a failure.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include <fmt/format.h>

#include "emulator/sim/cycle_scheduler.h"
#include "emulator/sim/event_loop.h"

namespace wheelhil::emulator::sim {
namespace {

using ::testing::ElementsAre;

// Steps of 10 ns; the log names every stage call "stage@t".
class FakeRun final : public RunStages, public FirmwareGate {
 public:
  explicit FakeRun(RunContext& run) : run_(run) {}
  std::int64_t step_ns() const override { return 10; }
  bool StepPhysics(std::int64_t t, bool) override {
    Log("physics", t);
    return true;
  }
  void StepDevices(std::int64_t t, bool) override { Log("devices", t); }
  void RecordTruth(std::int64_t t, bool force) override {
    if (force) Log("truth!", t);
  }
  void AdvanceBus(std::int64_t t) override {
    bus_ns_ = t;
    if (t % 10 != 0) Log("bus", t);  // the half-step flushes only
  }
  std::int64_t bus_now_ns() const override { return bus_ns_; }
  void SendSync(std::int64_t t) override { Log("sync", t); }
  void Drain() override {
    Log("drain", run_.now_ns);
    if (fail_at_ == run_.now_ns) run_.Fail("the firmware exited");
  }
  void AfterLastCycle() override { Log("last", run_.now_ns); }

  std::vector<std::string> log;
  std::int64_t fail_at_ = -1;

 private:
  void Log(const char* what, std::int64_t t) { log.push_back(fmt::format("{}@{}", what, t)); }
  RunContext& run_;
  std::int64_t bus_ns_ = 0;
};

// Two cycles of two steps from t = 0 (SYNCs at 0, 20 and the closing one at 40).
std::vector<std::string> Motion(FakeRun& fake, RunContext& run) {
  LockstepWait wait;
  EventLoop loop(run, wait);
  StepSource steps(fake, fake, run);
  steps.Start({.motion = true, .record_truth = true, .steps = 4});
  SyncSource sync(fake, fake, run, steps, 0, 20, 2);
  loop.Run({"motion", {&steps, &sync}, nullptr});
  std::vector<std::string> out;
  for (const auto& l : fake.log) {
    if (!l.starts_with("physics")) out.push_back(l);
  }
  return out;
}

TEST(CycleScheduler, EveryStepDrainsTheFirmwareAndTheLastSyncClosesTheLastCycle) {
  RunContext run;
  FakeRun fake(run);
  EXPECT_THAT(Motion(fake, run),
              ElementsAre("truth!@0", "sync@0", "bus@5", "devices@10", "drain@10", "devices@20",
                          "drain@20", "truth!@20", "sync@20", "bus@25", "devices@30", "drain@30",
                          "devices@40", "drain@40", "truth!@40", "sync@40", "bus@45", "last@40"));
}

TEST(CycleScheduler, AfterAFailureTheCycleRunsOutAndTheNextSyncEndsThePhase) {
  RunContext run;
  FakeRun fake(run);
  fake.fail_at_ = 10;
  EXPECT_THAT(Motion(fake, run), ElementsAre("truth!@0", "sync@0", "bus@5", "devices@10",
                                             "drain@10", "devices@20", "drain@20"));
  EXPECT_EQ(run.failure, "the firmware exited");
}

TEST(CycleScheduler, StartUpDrainsTheFirmwareAfterEveryStep) {
  RunContext run;
  FakeRun fake(run);
  LockstepWait wait;
  EventLoop loop(run, wait);
  StepSource steps(fake, fake, run);
  steps.Start({.motion = false, .record_truth = true, .steps = 2});
  loop.Run({"boot", {&steps}, nullptr});
  EXPECT_THAT(fake.log, ElementsAre("physics@10", "devices@10", "drain@10", "physics@20",
                                    "devices@20", "drain@20"));
}

}  // namespace
}  // namespace wheelhil::emulator::sim
