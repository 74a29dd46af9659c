// The run's step and SYNC sources (emulator/sim/cycle_scheduler.h) on fake stages and a fake
// firmware gate: the order of the stages in a cycle, when lockstep waits for a cycle's status,
// a cycle closed by the next SYNC, the last cycle, failures and real time.
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
  int SendSync(std::int64_t t) override {
    Log("sync", t);
    return syncs_++;
  }
  bool lockstep() const override { return lockstep_; }
  void Drain() override { Log("drain", run_.now_ns); }
  void WaitBootAnswers() override { Log("boot-wait", run_.now_ns); }
  bool CycleCompleteOnBus() const override { return complete_; }
  bool LatestSyncOnWire() const override { return true; }
  void WaitStatus(int cycle, std::int64_t k) override {
    log.push_back(fmt::format("status{}/{}@{}", cycle, k, run_.now_ns));
    if (fail_status_) run_.Fail("timeout");
  }
  void WaitLastStatus(int cycle, std::int64_t) override {
    log.push_back(fmt::format("last{}@{}", cycle, run_.now_ns));
  }

  std::vector<std::string> log;
  bool lockstep_ = true, complete_ = true, fail_status_ = false;

 private:
  void Log(const char* what, std::int64_t t) { log.push_back(fmt::format("{}@{}", what, t)); }
  RunContext& run_;
  std::int64_t bus_ns_ = 0;
  int syncs_ = 0;
};

// Two cycles of two steps from t = 0 (SYNCs at 0, 20 and the closing one at 40).
std::vector<std::string> Motion(FakeRun& fake, RunContext& run) {
  LockstepWait wait;
  EventLoop loop(run, wait);
  StepSource steps(fake, fake, run);
  steps.Start({.motion = true, .record_truth = true, .wait_boot_answers = false, .steps = 4});
  SyncSource sync(fake, fake, run, steps, 0, 20, 20, 2);
  loop.Run({"motion", {&steps, &sync}, nullptr});
  std::vector<std::string> out;
  for (const auto& l : fake.log) {
    if (!l.starts_with("physics")) out.push_back(l);
  }
  return out;
}

TEST(CycleScheduler, LockstepWaitsAfterTheFirstStepOfACompleteCycle) {
  RunContext run;
  FakeRun fake(run);
  EXPECT_THAT(Motion(fake, run),
              ElementsAre("truth!@0", "sync@0", "bus@5", "devices@10", "status0/0@10",
                          "devices@20", "truth!@20", "sync@20", "bus@25", "devices@30",
                          "status1/1@30", "devices@40", "truth!@40", "sync@40", "bus@45",
                          "last2@40"));
}

TEST(CycleScheduler, AnIncompleteCycleIsClosedByTheNextSync) {
  RunContext run;
  FakeRun fake(run);
  fake.complete_ = false;
  const auto log = Motion(fake, run);
  // Cycle 0 is awaited after SYNC 1 is on the wire; the last cycle, never complete, is not:
  // the bus gets one more period (half steps) to finish it.
  EXPECT_THAT(log, ElementsAre("truth!@0", "sync@0", "bus@5", "devices@10", "devices@20",
                               "truth!@20", "sync@20", "bus@25", "status0/0@20", "devices@30",
                               "devices@40", "truth!@40", "sync@40", "bus@45", "status1/1@40",
                               "bus@55"));
  ASSERT_FALSE(run.events.empty());
  EXPECT_EQ(run.events.back()["event"], "last_cycle_incomplete");
}

TEST(CycleScheduler, AfterAFailureTheCycleRunsOutAndTheNextSyncEndsThePhase) {
  RunContext run;
  FakeRun fake(run);
  fake.fail_status_ = true;
  EXPECT_THAT(Motion(fake, run), ElementsAre("truth!@0", "sync@0", "bus@5", "devices@10",
                                             "status0/0@10", "devices@20"));
  EXPECT_EQ(run.failure, "timeout");
}

TEST(CycleScheduler, RealTimeDrainsEveryStepAndWaitsOnlyForTheLastStatus) {
  RunContext run;
  FakeRun fake(run);
  fake.lockstep_ = false;
  fake.complete_ = false;  // ignored in real time
  EXPECT_THAT(Motion(fake, run),
              ElementsAre("truth!@0", "sync@0", "bus@5", "devices@10", "drain@10", "devices@20",
                          "drain@20", "truth!@20", "sync@20", "bus@25", "devices@30", "drain@30",
                          "devices@40", "drain@40", "truth!@40", "sync@40", "bus@45",
                          "last2@40"));
}

TEST(CycleScheduler, StartUpWaitsForBootAnswersAfterEveryStep) {
  RunContext run;
  FakeRun fake(run);
  LockstepWait wait;
  EventLoop loop(run, wait);
  StepSource steps(fake, fake, run);
  steps.Start({.motion = false, .record_truth = true, .wait_boot_answers = true, .steps = 2});
  loop.Run({"boot", {&steps}, nullptr});
  EXPECT_THAT(fake.log, ElementsAre("physics@10", "devices@10", "boot-wait@10", "physics@20",
                                    "devices@20", "boot-wait@20"));
}

}  // namespace
}  // namespace wheelhil::emulator::sim
