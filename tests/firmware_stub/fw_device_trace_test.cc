// The recorded device trace of the end-to-end test (tests/firmware_stub/fw_ucan_replay.sh): a
// paper 000 platform as the emulator drives it (boot-ups, SDO answers, heartbeats, the emulator
// as SYNC producer, TPDO1 after every SYNC, the MM5.10 yaw rate every 10 ms, and some bad
// traffic), built here through the DBC files, and the firmware outputs that trace must give.
// Both are committed under tests/data/firmware/; WHEELHIL_UPDATE_GOLDEN=1 rewrites them.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fmt/format.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "bus/candump_log.h"
#include "firmware_stub/fw_app.h"
#include "tests/firmware_stub/fw_test_devices.h"

namespace wheelhil::fw {
namespace {

using testing::Devices;

constexpr std::int64_t kMs = 1'000'000;
constexpr int kCycles = 60;
constexpr double kPeriodS = 0.05;
constexpr double kTrackM = 0.5, kRadiusM = 0.075, kCpr = 2000;

std::string DataDir() { return std::string(WHEELHIL_SOURCE_DIR) + "/tests/data/firmware"; }

std::uint32_t Counts(double m) {
  return static_cast<std::uint32_t>(
      static_cast<std::int64_t>(std::llround(m / (2 * M_PI * kRadiusM) * kCpr)));
}

/// Yaw rate of the trace's motion at time t (s since the first SYNC): a left turn in the middle.
double YawRate(int cycle) { return cycle >= 20 && cycle < 40 ? 0.2 : 0.0; }

std::vector<bus::CandumpRecord> BuildTrace() {
  const Devices dev;
  std::vector<bus::CandumpRecord> out;
  auto add = [&](std::int64_t t, const bus::CanFrame& f) { out.push_back({t, "vcan0", f, 0}); };
  // Start-up: boot-ups, then the answers to the two SDO downloads the firmware sends.
  add(50 * kMs, dev.Boot(1));
  add(50 * kMs, dev.Boot(2));
  const std::vector<std::string> requests = {"2F00180201000000", "2B17100064000000"};
  for (std::size_t i = 0; i < requests.size(); ++i) {
    for (int node : {1, 2}) {
      const auto req = testing::Frame(fmt::format("{:03X}#{}", 0x600 + node, requests[i]));
      // Answers 150 ms apart: a recorded trace cannot wait for the request, so leave a slow
      // (e.g. user-mode-linux) firmware time to send it first.
      add((200 + 150 * static_cast<std::int64_t>(i)) * kMs, dev.SdoAnswer(req));
    }
  }
  const std::int64_t t0 = 700 * kMs;
  const std::int64_t period = static_cast<std::int64_t>(kPeriodS * 1e3) * kMs;
  std::int64_t next_beat = 450 * kMs;
  double left = 0.0, right = 0.0;
  for (int k = 0; k < kCycles; ++k) {
    const std::int64_t sync = t0 + k * period;
    // Heartbeats and the IMU (10 ms) in the interval before this SYNC.
    for (std::int64_t t = sync - period + 10 * kMs; t <= sync; t += 10 * kMs) {
      while (next_beat <= t) {
        add(next_beat, dev.State(1, 0x05));
        add(next_beat, dev.State(2, 0x05));
        next_beat += 100 * kMs;
      }
      if (t < sync && k > 0) add(t + 1 * kMs, dev.Yaw(YawRate(k)));
    }
    if (k == 54) {  // Garbage: TPDO1 with DLC 2, an unknown id.
      add(sync - 2 * kMs, testing::Frame("181#0102"));
      add(sync - 2 * kMs, testing::Frame("321#DEADBEEF"));
    }
    add(sync, testing::Frame("080#"));  // The emulator is the SYNC producer here.
    // The wheels over the interval that ends at this SYNC: 0.25 m/s, turning at YawRate; a
    // 10 mm spin of the right wheel in cycle 45.
    if (k > 0) {
      const double ds = 0.25 * kPeriodS;
      const double dd = kTrackM * YawRate(k) * kPeriodS;
      left += ds - dd / 2;
      right += ds + dd / 2 + (k == 45 ? 0.010 : 0.0);
    }
    add(sync + kMs / 2, dev.Tpdo(1, Counts(left)));
    if (k == 52) add(sync + kMs / 2, dev.Tpdo(1, Counts(left)));   // Duplicated.
    if (k != 50) add(sync + 800'000, dev.Tpdo(2, Counts(right)));  // Node 2 misses cycle 50.
  }
  std::stable_sort(out.begin(), out.end(),
                   [](const auto& a, const auto& b) { return a.timestamp_ns < b.timestamp_ns; });
  return out;
}

/// Runs the trace through the app in virtual time; returns its output frames (can-utils text).
std::vector<std::string> RunApp(const std::vector<bus::CandumpRecord>& trace) {
  const FwConfig c = LoadFwConfig(DataDir() + "/paper000_ucan.yaml");
  const FwProtocol p = FwProtocol::LoadDir(testing::DbcDir(), {1, 2}, 0x174, 0);
  FwApp app(c, p);
  std::vector<bus::CanFrame> out;
  std::vector<std::string> outputs;
  auto take = [&] {
    for (const auto& f : out) {
      if (f.id >= 0x680 && f.id <= 0x686) outputs.push_back(bus::ToCanUtilsString(f));
    }
    out.clear();
  };
  app.Start(0, out);
  take();
  for (const auto& r : trace) {
    while (app.NextEventNs() < r.timestamp_ns) {
      app.Poll(app.NextEventNs(), out);
      take();
    }
    app.OnFrame(r.frame, r.timestamp_ns, out);
    take();
  }
  app.Poll(trace.back().timestamp_ns + 1000 * kMs, out);
  take();
  return outputs;
}

std::string Slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void CompareOrUpdate(const std::string& path, const std::string& text) {
  if (const char* u = std::getenv("WHEELHIL_UPDATE_GOLDEN"); u && std::string(u) == "1") {
    std::ofstream(path) << text;
    GTEST_SKIP() << "rewrote " << path;
  }
  EXPECT_EQ(Slurp(path), text) << path << " (WHEELHIL_UPDATE_GOLDEN=1 rewrites it)";
}

TEST(FwDeviceTrace, CommittedTraceIsTheDeviceModel) {
  std::string text =
      "# wheelhil-fw end-to-end trace (paper 000 devices); see fw_device_trace_test.cc\n";
  for (const auto& r : BuildTrace()) {
    text += bus::FormatCandumpLine(r.timestamp_ns, r.interface, r.frame) + "\n";
  }
  CompareOrUpdate(DataDir() + "/paper000_devices.log", text);
}

TEST(FwDeviceTrace, AppGivesTheCommittedOutputs) {
  const auto outputs = RunApp(BuildTrace());
  ASSERT_EQ(outputs.size(), static_cast<std::size_t>(kCycles) * 5);
  std::string text;
  for (const auto& s : outputs) text += s + "\n";
  CompareOrUpdate(DataDir() + "/paper000_expected_outputs.txt", text);
}

TEST(FwDeviceTrace, TraceExercisesTheEstimatorAndTheFaultPaths) {
  const FwProtocol p = FwProtocol::LoadDir(testing::DbcDir(), {1, 2}, 0x174, 0);
  const auto outputs = RunApp(BuildTrace());
  int slips_right = 0, bad = 0, degraded = 0;
  OutValues last_pose;
  for (const auto& s : outputs) {
    const bus::CanFrame f = testing::Frame(s);
    OutValues v;
    if (p.DecodeOutput(OutMessage::kSlipStatus, f, v))
      slips_right += v.Get(OutField::kSlipRight) == 1;
    if (p.DecodeOutput(OutMessage::kStatus, f, v)) {
      bad += v.Get(OutField::kFaultBadFrame) == 1;
      degraded += v.Get(OutField::kState) == static_cast<double>(FwState::kDegraded);
    }
    if (p.DecodeOutput(OutMessage::kPose, f, v)) last_pose = v;
  }
  EXPECT_EQ(slips_right, 1);  // Cycle 45.
  EXPECT_EQ(bad, 1);          // Cycle 54.
  EXPECT_EQ(degraded, 2);     // Missing TPDO (50), duplicate (52).
  // 59 steps of 12.5 mm, 20 of them turning 10 mrad each: heading 0.2 rad.
  EXPECT_NEAR(last_pose.Get(OutField::kTheta), 0.2, 1e-3);
  EXPECT_GT(last_pose.Get(OutField::kX), 0.6);
  EXPECT_GT(last_pose.Get(OutField::kY), 0.05);
}

}  // namespace
}  // namespace wheelhil::fw
