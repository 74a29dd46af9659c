// ResolveTiming: the run's one timing decision, as a table of cases (scenario timing block,
// command line, bus) -> (clock, SYNC producer), and the combination refused with its fix.
#include "emulator/scenario/timing_plan.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <optional>
#include <stdexcept>
#include <string>

namespace wheelhil::emulator::scenario {
namespace {

using Clock = TimingPlan::Clock;
using Pacing = firmware::FirmwareLink::Pacing;
using ::testing::HasSubstr;

struct Case {
  const char* what;
  // The scenario's timing block: timing.mode lockstep, timing.sync_producer (nullopt: not
  // named).
  bool lockstep_mode;
  std::optional<bool> firmware_sync;
  // The command line and the bus.
  bool realtime;
  const char* can_iface;
  bool firmware_command;
  // The plan, or the error that refuses the combination.
  Clock clock;
  bool firmware_produces_sync;
  const char* error;
};

TimingChoice ChoiceOf(const Case& c) {
  TimingChoice choice;
  choice.spec.lockstep = c.lockstep_mode;
  choice.spec.sync_producer_named = c.firmware_sync.has_value();
  choice.spec.firmware_produces_sync = c.firmware_sync.value_or(true);
  choice.source_path = "robot.yaml";
  choice.realtime = c.realtime;
  choice.can_iface = c.can_iface;
  choice.firmware_command = c.firmware_command;
  return choice;
}

constexpr const char* kOk = nullptr;
// clang-format off
const Case kCases[] = {
    {"the defaults", true, {}, false, "", true, Clock::kVirtual, true, kOk},
    {"the emulator's SYNC", true, false, false, "", true, Clock::kVirtual, false, kOk},
    {"--realtime", true, {}, true, "", true, Clock::kWall, true, kOk},
    {"timing.mode: realtime", false, {}, false, "", true, Clock::kWall, true, kOk},
    {"real time, the emulator's SYNC", false, false, false, "", true, Clock::kWall, false, kOk},
    {"--realtime, the firmware's SYNC", true, true, true, "", true, Clock::kWall, true, kOk},
    {"a kernel interface", true, {}, false, "vcan0", true, Clock::kVirtual, true, kOk},
    {"a kernel interface, the emulator's SYNC", true, false, false, "vcan0", true,
     Clock::kVirtual, false, kOk},
    {"a kernel interface, real time", true, {}, true, "vcan0", true, Clock::kWall, true, kOk},
    {"an attached firmware, real time", true, {}, true, "", false, Clock::kWall, true, kOk},
    {"an attached firmware in lockstep", true, {}, false, "", false, Clock::kWall, false,
     "a firmware attached from outside (no firmware.command) keeps its own clock, so it cannot "
     "run in lockstep: run it with --realtime"},
    {"an attached firmware on a kernel interface", true, {}, false, "vcan0", false, Clock::kWall,
     false, "cannot run in lockstep"},
};
// clang-format on

TEST(TimingPlan, EveryCombinationOfScenarioCommandLineAndBusHasOnePlanOrARefusal) {
  for (const Case& c : kCases) {
    SCOPED_TRACE(c.what);
    if (c.error != nullptr) {
      try {
        (void)ResolveTiming(ChoiceOf(c));
        ADD_FAILURE() << "accepted";
      } catch (const std::invalid_argument& e) {
        EXPECT_THAT(e.what(), HasSubstr("robot.yaml: "));
        EXPECT_THAT(e.what(), HasSubstr(c.error));
      }
      continue;
    }
    const TimingPlan plan = ResolveTiming(ChoiceOf(c));
    EXPECT_EQ(plan.clock, c.clock);
    EXPECT_EQ(plan.firmware_produces_sync, c.firmware_produces_sync);
    EXPECT_EQ(plan.kernel_bus, std::string(c.can_iface) != "");
  }
}

TEST(TimingPlan, TheLinkAndTheEventsReadTheClockFromThePlan) {
  TimingPlan p;
  p.clock = Clock::kVirtual;
  EXPECT_EQ(p.pacing(), Pacing::kVirtualClock);
  EXPECT_TRUE(p.lockstep());
  EXPECT_STREQ(p.clock_name(), "virtual");
  p.clock = Clock::kWall;
  EXPECT_EQ(p.pacing(), Pacing::kRealTime);
  EXPECT_FALSE(p.lockstep());
  EXPECT_STREQ(p.clock_name(), "wall");
}

}  // namespace
}  // namespace wheelhil::emulator::scenario
