// Scenario fault entries (docs/scenarios.md `faults`): parsing with file:line:column errors, and
// end-to-end runs with the reference firmware on a private userspace bus (paper-000 platform,
// 2.5 s): a frame drop with probability 1 removes exactly the frames due in its window from
// can.log; a per-wheel friction drop makes that wheel slip (ground truth) and not the other; a
// braking disturbance torque on the left wheel turns the robot left; the same seed gives the same
// can.log and events.jsonl with random faults, another seed does not.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bus/ucan_runtime_dir.h"
#include "emulator/scenario/runner.h"
#include "emulator/scenario/scenario.h"
#include "tests/emulator/scenario/runner_test_support.h"

namespace wheelhil::emulator::scenario {
namespace {

namespace fs = std::filesystem;
using ::testing::AllOf;
using ::testing::HasSubstr;
using testing::Slurp;
using ::testing::ThrowsMessage;

RunOptions Options(const fs::path& out) { return testing::BuildTreeRunOptions(out); }

const std::string kBasePath = std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/paper000_slip.yaml";

// paper000_slip.yaml with a `faults:` list appended (`entries`: lines without the list key).
std::string WithFaults(const std::string& entries) {
  return Slurp(kBasePath) + "faults:\n" + entries;
}

int LineCount(const std::string& s) {
  return static_cast<int>(std::count(s.begin(), s.end(), '\n'));
}

// The message thrown by parsing `entries`; expects "file:LINE:COL: FIELD: ..." where LINE is the
// line of the entries (1-based) holding `at`, COL the column of `at` in it.
void ExpectError(const std::string& entries, int entry_line, const std::string& at,
                 const std::string& field, const std::string& problem) {
  const std::string base = Slurp(kBasePath);
  const std::string text = base + "faults:\n" + entries;
  std::istringstream in(entries);
  std::string line;
  for (int i = 0; i < entry_line; ++i) std::getline(in, line);
  const auto col = line.find(at);
  ASSERT_NE(col, std::string::npos) << at;
  const int file_line = LineCount(base) + 1 + entry_line;
  const std::string where = kBasePath + ":" + std::to_string(file_line) + ":" +
                            std::to_string(col + 1) + ": " + field + ": ";
  try {
    (void)ParseScenario(text, kBasePath);
    ADD_FAILURE() << "no error for " << entries;
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr(where)) << e.what();
    EXPECT_THAT(e.what(), HasSubstr(problem)) << e.what();
  }
}

TEST(ScenarioFaultsParse, EveryKindParses) {
  const Scenario s = ParseScenario(
      WithFaults(
          "  - {type: frame, kind: drop, id: 0x174, probability: 0.5, start_s: 1, end_s: 2}\n"
          "  - {type: frame, kind: delay, id: 0x181, delay_s: 0.003, start_s: 1}\n"
          "  - {type: frame, kind: corrupt, id: 0x100, mask: 0x700, bit_flips: 2, "
          "start_s: 0}\n"
          "  - {type: bus, kind: flood, load: 0.3, flood_id: 0x002, start_s: 1, end_s: 2}\n"
          "  - {type: bus, kind: bus_off, node_id: 2, start_s: 1, end_s: 1.5}\n"
          "  - {type: bus, kind: error_burst, error_frames: 5, start_s: 1}\n"
          "  - {type: sensor, sensor: gyro, kind: bias_step, value: 0.01, start_s: 1}\n"
          "  - {type: sensor, sensor: encoder, wheel: left, kind: missed_counts, value: 0.1, "
          "start_s: 1, end_s: 2}\n"
          "  - {type: sensor, sensor: gyro, kind: stuck, start_s: 3, end_s: 4}\n"
          "  - {type: device, kind: reboot, node_id: 1, start_s: 2, end_s: 2.2}\n"
          "  - {type: device, kind: heartbeat_lost, node_id: 2, start_s: 2}\n"
          "  - {type: device, kind: silent, node: gyro, start_s: 2, end_s: 3}\n"
          "  - {type: wheel_friction, wheel: left, mu_scale: 0.1, start_s: 1, end_s: 2}\n"
          "  - {type: wheel_friction, wheel: right, mu_peak: 0.1, mu_slide: 0.05, "
          "start_s: 1, end_s: 2}\n"
          "  - {type: torque_disturbance, wheel: right, torque_nm: -1.5, start_s: 1, "
          "end_s: 2}\n"
          "  - {type: bump, x_m: 2.0, height_m: 0.01}\n"
          "  - {type: encoder_silent, node_id: 1, start_s: 1, end_s: 2}\n"),
      kBasePath);
  ASSERT_EQ(s.faults.size(), 17u);
  const auto& f = s.faults;
  EXPECT_EQ(f[0].kind, FaultSpec::Kind::kFrame);
  EXPECT_EQ(f[0].frame.kind, FrameFaultKind::kDrop);
  EXPECT_EQ(f[0].frame.id, 0x174u);
  EXPECT_EQ(f[0].frame.mask, 0x7FFu);
  EXPECT_DOUBLE_EQ(f[0].frame.probability, 0.5);
  EXPECT_EQ(f[0].frame.window.t0_ns, 1'000'000'000);
  EXPECT_EQ(f[0].frame.window.t1_ns, 2'000'000'000);
  EXPECT_EQ(f[1].frame.delay_ns, 3'000'000);
  EXPECT_EQ(f[1].frame.window.t1_ns, FaultWindow::kForever);
  EXPECT_EQ(f[2].frame.mask, 0x700u);
  EXPECT_EQ(f[3].bus.kind, BusFaultKind::kFlood);
  EXPECT_EQ(f[3].bus.flood_id, 0x002u);
  EXPECT_EQ(f[4].node_id, 2);
  EXPECT_EQ(f[5].bus.error_frames, 5);
  EXPECT_EQ(f[6].sensor_name, "gyro");
  EXPECT_EQ(f[7].sensor.kind, SensorFaultKind::kMissedCounts);
  EXPECT_EQ(f[7].wheel, "left");
  EXPECT_EQ(f[9].device.kind, DeviceFaultKind::kReboot);
  EXPECT_EQ(f[11].node, "gyro");
  EXPECT_DOUBLE_EQ(f[12].mu_scale, 0.1);
  EXPECT_FALSE(f[12].mu_override.has_value());
  ASSERT_TRUE(f[13].mu_override.has_value());
  EXPECT_DOUBLE_EQ(f[13].mu_override->mu_slide, 0.05);
  EXPECT_EQ(f[14].wheel_index, s.platform.wheel_index("right"));
  EXPECT_DOUBLE_EQ(f[14].torque_nm, -1.5);
  EXPECT_DOUBLE_EQ(f[15].ramp_length_m, 0.04);  // default: 4 x height
  EXPECT_EQ(f[16].kind, FaultSpec::Kind::kEncoderSilent);
}

TEST(ScenarioFaultsParse, ErrorsNameFileLineColumnAndField) {
  ExpectError("  - {type: frame, kind: smash, start_s: 1}\n", 1, "smash", "faults[0].kind",
              "'smash' is not one of drop, delay");
  ExpectError("  - {type: frame, kind: drop, probability: 1.5, start_s: 1}\n", 1, "1.5",
              "faults[0].probability", "(1.5) must be in [0, 1]");
  ExpectError("  - {type: frame, kind: drop, id: 0x900, start_s: 1}\n", 1, "0x900", "faults[0].id",
              "beyond 0x7FF");
  ExpectError("  - {type: frame, kind: delay, id: 0x174, start_s: 1}\n", 1, "{type",
              "faults[0].delay_s", "is required");
  ExpectError(
      "  - {type: bus, kind: flood, start_s: 1}\n  - {type: bus, kind: flood, load: 2, start_s: "
      "1}\n",
      2, "2,", "faults[1].load", "(2) must be in [0.001, 1]");
  ExpectError("  - {type: bus, kind: bus_off, node_id: 9, start_s: 1}\n", 1, "9,",
              "faults[0].node_id", "no encoder node has this id");
  ExpectError("  - {type: sensor, sensor: accel4, kind: bias_step, value: 1, start_s: 1}\n", 1,
              "accel4", "faults[0].sensor", "sensors.accel4 is not configured");
  ExpectError("  - {type: sensor, sensor: gyro, kind: missed_counts, value: 0.1, start_s: 1}\n", 1,
              "missed_counts", "faults[0].kind", "encoders only");
  ExpectError("  - {type: sensor, sensor: gyro, kind: noise_scale, value: 0.5, start_s: 1}\n", 1,
              "0.5", "faults[0].value", "noise factor k (0.5) must be >= 1");
  ExpectError("  - {type: device, kind: reboot, node_id: 1, start_s: 1}\n", 1, "{type",
              "faults[0].end_s", "is required for a reboot");
  ExpectError("  - {type: device, kind: reboot, node: gyro, start_s: 1, end_s: 2}\n", 1, "{type",
              "faults[0].node_id", "is required");
  ExpectError("  - {type: wheel_friction, wheel: middle, mu_scale: 0.1, start_s: 1, end_s: 2}\n", 1,
              "middle", "faults[0].wheel", "platform diff2 has no wheel 'middle'");
  ExpectError("  - {type: wheel_friction, wheel: left, mu_scale: -1, start_s: 1, end_s: 2}\n", 1,
              "-1", "faults[0].mu_scale", "(-1) must be in [0, 10]");
  ExpectError("  - {type: torque_disturbance, wheel: left, start_s: 1, end_s: 2}\n", 1, "{type",
              "faults[0].torque_nm", "is required");
  ExpectError("  - {type: torque_disturbance, wheel: left, torque_nm: 1, start_s: 2, end_s: 1}\n",
              1, "1}", "faults[0].end_s", "(1) must be in [2, ");
  ExpectError("  - {type: bump, x_m: 1}\n", 1, "{type", "faults[0].height_m", "is required");
  ExpectError("  - {type: frame, kind: drop, start_s: 1, prob: 1}\n", 1, "prob", "faults[0].prob",
              "unknown key");
  ExpectError("  - {type: meteor, start_s: 1}\n", 1, "meteor", "faults[0].type",
              "'meteor' is not one of encoder_emcy, encoder_silent, frame, bus, sensor, device, "
              "drive, wheel_friction, torque_disturbance, bump");
}

// ---- End to end -----------------------------------------------------------------------------

// Paper-000 robot on a uniform floor (no random spots): 0.3 s hold, then 0.5 m with a 0.5 m/s^2
// trapezoid (accelerating over motion time 0.3..0.8 s), 2.5 s in all, 4 Hz SYNC.
Scenario Short(const std::string& fault_entries) {
  Scenario s = ParseScenario(fault_entries.empty() ? Slurp(kBasePath) : WithFaults(fault_entries),
                             kBasePath);
  s.terrain.random_patches.count = 0;
  s.motion = ParseScenario(Slurp(kBasePath), kBasePath).motion;
  s.motion[0].duration_s = 0.3;
  s.motion[1].distance = 0.5;
  s.motion[1].duration_s = TrapezoidDuration(0.5, 0.25, 0.5);
  s.motion.resize(2);
  s.timing.duration_s = 2.5;
  s.expectations.clear();
  return s;
}

struct LogFrame {
  std::int64_t t_us = 0;
  std::uint32_t id = 0;
  std::string data;
};

std::vector<LogFrame> ReadLog(const fs::path& p) {
  std::vector<LogFrame> out;
  std::istringstream in(Slurp(p));
  std::string line;
  while (std::getline(in, line)) {
    long sec = 0, usec = 0;
    char iface[32] = {0}, frame[64] = {0};
    if (std::sscanf(line.c_str(), "(%ld.%ld) %31s %63s", &sec, &usec, iface, frame) != 4) continue;
    const std::string f = frame;
    const auto hash = f.find('#');
    if (hash == std::string::npos) continue;
    LogFrame lf;
    lf.t_us = sec * 1'000'000 + usec;
    lf.id = static_cast<std::uint32_t>(std::stoul(f.substr(0, hash), nullptr, 16));
    lf.data = f.substr(hash + 1);
    out.push_back(lf);
  }
  return out;
}

class ScenarioFaultsRun : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           fs::path("wheelhil_scenario_faults_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  nlohmann::json Run(const Scenario& s, const std::string& name,
                     std::optional<std::uint64_t> seed = std::nullopt) {
    RunOptions o = Options(dir_ / name);
    o.seed = seed;
    const RunResult r = RunScenario(s, o);
    EXPECT_EQ(r.failure, "") << name;
    return r.report;
  }
  fs::path dir_;
};

TEST_F(ScenarioFaultsRun, FrameDropRemovesExactlyTheFramesDueInItsWindow) {
  // The emulator's SYNCs mark the motion start here.
  Scenario plain = Short("");
  testing::UseEmulatorSync(plain);
  (void)Run(plain, "base");
  Scenario with_drop =
      Short("  - {type: frame, kind: drop, id: 0x174, probability: 1, start_s: 1.0, end_s: 1.5}\n");
  testing::UseEmulatorSync(with_drop);
  const nlohmann::json r = Run(with_drop, "drop");
  const auto base = ReadLog(dir_ / "base" / "can.log");
  const auto drop = ReadLog(dir_ / "drop" / "can.log");
  // Motion start: the first SYNC (0x080) is queued at that (whole-ms) instant, done within 1 ms.
  auto motion0_us = [](const std::vector<LogFrame>& log) {
    for (const auto& f : log) {
      if (f.id == 0x080) return f.t_us / 1000 * 1000;
    }
    return std::int64_t{-1};
  };
  const std::int64_t t0 = motion0_us(base);
  ASSERT_GT(t0, 0);
  ASSERT_EQ(motion0_us(drop), t0);
  // Gyro frames are due every 10 ms of virtual time and complete well within 10 ms.
  auto gyro = [](const std::vector<LogFrame>& log) {
    std::vector<std::pair<std::int64_t, std::string>> out;
    for (const auto& f : log) {
      if (f.id == 0x174) out.emplace_back(f.t_us / 10'000 * 10'000, f.data);
    }
    return out;
  };
  std::vector<std::pair<std::int64_t, std::string>> expected;
  int in_window = 0;
  for (const auto& g : gyro(base)) {
    if (g.first >= t0 + 1'000'000 && g.first < t0 + 1'500'000) {
      ++in_window;
    } else {
      expected.push_back(g);
    }
  }
  EXPECT_EQ(in_window, 50);
  EXPECT_EQ(gyro(drop), expected);
  // Every other emulated device frame is unchanged in number and content.
  auto others = [](const std::vector<LogFrame>& log) {
    std::map<std::uint32_t, std::vector<std::string>> out;
    for (const auto& f : log) {
      if (f.id == 0x080 || f.id == 0x181 || f.id == 0x182 || f.id == 0x701 || f.id == 0x702) {
        out[f.id].push_back(f.data);
      }
    }
    return out;
  };
  EXPECT_EQ(others(drop), others(base));
  EXPECT_EQ(r["metrics"]["faults"]["frames_affected"].get<int>(), 50);
  const std::string events = Slurp(dir_ / "drop" / "events.jsonl");
  EXPECT_THAT(events, HasSubstr("\"event\":\"fault_start\""));
  EXPECT_THAT(events, HasSubstr("\"event\":\"fault_end\""));
  EXPECT_THAT(events, HasSubstr("\"target\":\"id 0x174 mask 0x7FF\""));
}

TEST_F(ScenarioFaultsRun, WheelFrictionDropSlipsThatWheelOnly) {
  // Left wheel's mu x 0.02 while the robot accelerates (motion time 0.3..0.8 s).
  const Scenario s =
      Short("  - {type: wheel_friction, wheel: left, mu_scale: 0.02, start_s: 0.3, end_s: 0.8}\n");
  const nlohmann::json r = Run(s, "mu");
  std::size_t left_bit = 99, right_bit = 99;
  for (std::size_t i = 0; i < s.platform.drive_wheels.size(); ++i) {
    if (s.platform.drive_wheels[i] == s.platform.wheel_index("left")) left_bit = i;
    if (s.platform.drive_wheels[i] == s.platform.wheel_index("right")) right_bit = i;
  }
  ASSERT_LT(left_bit, 2u);
  ASSERT_LT(right_bit, 2u);
  std::istringstream in(Slurp(dir_ / "mu" / "truth.csv"));
  std::string line;
  std::getline(in, line);  // header
  int left_in = 0, left_out = 0, right_any = 0;
  while (std::getline(in, line)) {
    double t = 0;
    int bits = 0;
    const auto last = line.rfind(',');
    t = std::stod(line.substr(0, line.find(',')));
    bits = std::stoi(line.substr(last + 1));
    const bool left = bits & (1 << left_bit), right = bits & (1 << right_bit);
    if (left && t >= 0.3 && t <= 0.85) ++left_in;
    if (left && (t < 0.3 || t > 1.0)) ++left_out;
    if (right) ++right_any;
  }
  EXPECT_GT(left_in, 10);
  EXPECT_EQ(left_out, 0);
  EXPECT_EQ(right_any, 0);
  const auto& m = r["metrics"];
  EXPECT_GE(m["truth"]["slip_intervals"].get<int>(), 1);
  ASSERT_TRUE(m.contains("slip"));
  EXPECT_GE(m["slip"]["truth_intervals"].get<int>(), 1);
  EXPECT_TRUE(m["slip"].contains("recall"));
  EXPECT_TRUE(m["slip"].contains("precision"));
  EXPECT_THAT(Slurp(dir_ / "mu" / "events.jsonl"), HasSubstr("\"fault\":\"wheel_friction\""));
}

TEST(ScenarioPlatformTolerances, SampleOrNominalElseALocatedError) {
  const std::string text = Slurp(kBasePath);
  const std::string key = "  file: platforms/diff2.yaml\n";
  ASSERT_NE(text.find(key), std::string::npos);
  auto with = [&](const std::string& line) {
    std::string t = text;
    t.insert(t.find(key) + key.size(), line);
    return t;
  };
  EXPECT_TRUE(ParseScenario(text, kBasePath).sample_tolerances);  // the default
  EXPECT_FALSE(ParseScenario(with("  tolerances: nominal\n"), kBasePath).sample_tolerances);
  // The inserted line follows the file: line.
  const auto line = std::count(text.begin(), text.begin() + text.find(key), '\n') + 2;
  EXPECT_THAT([&] { (void)ParseScenario(with("  tolerances: random\n"), kBasePath); },
              ThrowsMessage<std::invalid_argument>(
                  AllOf(HasSubstr("paper000_slip.yaml:" + std::to_string(line) + ":"),
                        HasSubstr("platform.tolerances: must be 'sample' or 'nominal'"))));
}

TEST_F(ScenarioFaultsRun, PlatformTolerancesBuildEachRunsRobotFromItsSeed) {
  Scenario s = Short("");
  s.platform.tolerances.radius_m = 0.0005;
  s.platform.tolerances.mount_m = 0.002;
  Scenario nominal = Short("");
  nominal.sample_tolerances = false;
  (void)Run(nominal, "base");
  (void)Run(s, "built");
  const std::string events = Slurp(dir_ / "built" / "events.jsonl");
  std::size_t n = 0;
  for (std::size_t at = events.find("\"wheel_as_built\""); at != std::string::npos;
       at = events.find("\"wheel_as_built\"", at + 1)) {
    ++n;
  }
  EXPECT_EQ(n, s.platform.vehicle.wheels.size());
  EXPECT_THAT(events, HasSubstr("\"radius_dev_m\""));
  // The robot as built drives another path than the nominal one, the same for the same seed.
  EXPECT_NE(Slurp(dir_ / "built" / "truth.csv"), Slurp(dir_ / "base" / "truth.csv"));
  (void)Run(s, "again");
  EXPECT_EQ(Slurp(dir_ / "again" / "truth.csv"), Slurp(dir_ / "built" / "truth.csv"));
  // `platform.tolerances: nominal` builds the file's robot exactly.
  s.sample_tolerances = false;
  (void)Run(s, "nominal");
  EXPECT_EQ(Slurp(dir_ / "nominal" / "truth.csv"), Slurp(dir_ / "base" / "truth.csv"));
  EXPECT_THAT(Slurp(dir_ / "nominal" / "events.jsonl"),
              ::testing::Not(HasSubstr("wheel_as_built")));
}

TEST_F(ScenarioFaultsRun, BrakingTorqueOnTheLeftWheelTurnsLeft) {
  const nlohmann::json base = Run(Short(""), "base");
  (void)base;
  (void)Run(Short("  - {type: torque_disturbance, wheel: left, torque_nm: -6, start_s: 0.5, "
                  "end_s: 1.0}\n"),
            "tau");
  auto final_theta = [&](const std::string& name) {
    std::istringstream in(Slurp(dir_ / name / "truth.csv"));
    std::string line, last;
    std::getline(in, line);
    while (std::getline(in, line)) last = line;
    std::vector<std::string> cols;
    std::stringstream ss(last);
    for (std::string c; std::getline(ss, c, ',');) cols.push_back(c);
    return std::stod(cols.at(4));  // t,x,y,z,theta
  };
  const double th0 = final_theta("base"), th1 = final_theta("tau");
  EXPECT_LT(std::abs(th0), 0.01);
  EXPECT_GT(th1 - th0, 0.05);  // counter-clockwise: towards the braked left wheel
}

TEST_F(ScenarioFaultsRun, SameSeedSameLogWithRandomFaults) {
  const Scenario s = Short(
      "  - {type: frame, kind: drop, id: 0x174, probability: 0.3, start_s: 0.2, end_s: 2.0}\n"
      "  - {type: frame, kind: corrupt, id: 0x174, probability: 0.2, start_s: 0.2}\n"
      "  - {type: frame, kind: duplicate, id: 0x182, probability: 0.5, delay_s: 0.0005, "
      "start_s: 0.5}\n"
      "  - {type: sensor, sensor: gyro, kind: noise_scale, value: 3, start_s: 0.5, end_s: 1.5}\n"
      "  - {type: bus, kind: flood, load: 0.2, start_s: 1.0, end_s: 1.2}\n"
      "  - {type: device, kind: heartbeat_lost, node_id: 2, start_s: 1.0, end_s: 2.0}\n");
  const nlohmann::json a = Run(s, "a");
  const nlohmann::json b = Run(s, "b");
  const nlohmann::json c = Run(s, "c", 7);
  const std::string log_a = Slurp(dir_ / "a" / "can.log");
  EXPECT_EQ(log_a, Slurp(dir_ / "b" / "can.log"));
  EXPECT_EQ(Slurp(dir_ / "a" / "events.jsonl"), Slurp(dir_ / "b" / "events.jsonl"));
  EXPECT_NE(log_a, Slurp(dir_ / "c" / "can.log"));
  EXPECT_EQ(a["metrics"]["faults"], b["metrics"]["faults"]);
  EXPECT_GT(a["metrics"]["faults"]["flood_frames"].get<int>(), 0);
  EXPECT_GT(a["metrics"]["faults"]["device_suppressed_frames"].get<int>(), 0);
  const std::string events = Slurp(dir_ / "a" / "events.jsonl");
  for (const char* cat : {"\"category\":\"frame\"", "\"category\":\"sensor\"",
                          "\"category\":\"bus\"", "\"category\":\"device\""}) {
    EXPECT_THAT(events, HasSubstr(cat));
  }
}

// A rebooted encoder (power cycle while the robot drives) comes back with its absolute count: the
// firmware restarts it (boot-up -> SDO -> NMT start), spans the gap in one step, and its raw
// odometry ends where the run without the reboot ends (a counter restarting at zero would move
// the left wheel's travel by metres). Paper 000's no-slip floor, so only the reboot differs.
TEST_F(ScenarioFaultsRun, RebootedEncoderRecoversItsCount) {
  const std::string base_path =
      std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/paper000_calibration.yaml";
  Scenario s = LoadScenarioFile(base_path);
  s.motion[1].distance = 1.0;
  s.motion[1].duration_s = TrapezoidDuration(1.0, 0.25, 0.5);
  s.timing.duration_s = 0.5 + s.motion[1].duration_s + 0.5;
  s.expectations.clear();
  const nlohmann::json plain = Run(s, "plain");
  Scenario r =
      ParseScenario(Slurp(base_path) +
                        "faults:\n  - {type: device, kind: reboot, node_id: 1, start_s: 1.5, "
                        "end_s: 1.7}\n",
                    base_path);
  r.motion = s.motion;
  r.timing = s.timing;
  r.expectations.clear();
  const nlohmann::json rebooted = Run(r, "reboot");
  const std::string events = Slurp(dir_ / "reboot" / "events.jsonl");
  EXPECT_THAT(events, HasSubstr("\"fault\":\"reboot\""));
  // Off (255 is the emulator's "no heartbeat" state), boot-up, then operational again.
  std::vector<std::pair<double, int>> node1;
  std::istringstream in(events);
  std::string line;
  while (std::getline(in, line)) {
    const auto e = nlohmann::json::parse(line);
    if (e["event"] == "node_state" && e["node_id"] == 1) {
      node1.emplace_back(e["t_s"].get<double>(), e["state"].get<int>());
    }
  }
  ASSERT_GE(node1.size(), 4u);
  EXPECT_EQ(node1.back().second, 5);         // operational at the end
  EXPECT_GT(node1.back().first, 1.7);        // after the power-on
  EXPECT_LT(node1.back().first, 1.7 + 1.5);  // and well before the run ends
  const auto& a = plain["metrics"]["pose_raw"];
  const auto& b = rebooted["metrics"]["pose_raw"];
  EXPECT_GT(b["distance_m"].get<double>(), 0.95);
  EXPECT_NEAR(b["final_position_error_m"].get<double>(), a["final_position_error_m"].get<double>(),
              1e-3);
  EXPECT_NEAR(b["final_heading_error_rad"].get<double>(),
              a["final_heading_error_rad"].get<double>(), 1e-3);
  EXPECT_EQ(rebooted["verdict"], "pass");
}

// A node reboot (the firmware restarts it), then an error burst holding back the SYNC that
// closes the incomplete cycle, bus-off, missed counts, gyro dropout, EMCY and a wrong DLC: the
// lockstep run goes to the end and every fault shows in the metrics, can.log and events.
TEST_F(ScenarioFaultsRun, DeviceAndBusFaultsRunToTheEnd) {
  const nlohmann::json r = Run(
      Short("  - {type: device, kind: reboot, node_id: 1, start_s: 0.5, end_s: 0.6}\n"
            "  - {type: bus, kind: error_burst, error_frames: 5, start_s: 1.0}\n"
            "  - {type: bus, kind: bus_off, node_id: 2, start_s: 1.2, end_s: 1.6}\n"
            "  - {type: sensor, sensor: encoder, wheel: right, kind: missed_counts, value: 0.5, "
            "start_s: 0.3, end_s: 1.0}\n"
            "  - {type: sensor, sensor: gyro, kind: dropout, start_s: 1.5, end_s: 1.8}\n"
            "  - {type: device, kind: emcy, node_id: 2, start_s: 1.9, end_s: 2.1}\n"
            "  - {type: frame, kind: wrong_dlc, id: 0x174, dlc: 3, start_s: 2.0, end_s: 2.2}\n"),
      "dev");
  EXPECT_EQ(r["verdict"], "pass");
  const auto& f = r["metrics"]["faults"];
  EXPECT_EQ(f["error_frames"].get<int>(), 5);
  EXPECT_GT(f["bus_off_dropped"].get<int>(), 0);
  EXPECT_GT(f["missed_counts"].get<int>(), 0);
  EXPECT_EQ(f["frames_affected"].get<int>(), 20);  // 0x174 at 100 Hz for 0.2 s
  const std::string log = Slurp(dir_ / "dev" / "can.log");
  EXPECT_THAT(log, HasSubstr(" 20000088#0000000000000000"));  // error frames (CAN_ERR_FLAG)
  EXPECT_THAT(log, HasSubstr(" 174#"));
  const std::string events = Slurp(dir_ / "dev" / "events.jsonl");
  EXPECT_THAT(events, HasSubstr("\"fault\":\"reboot\""));
  EXPECT_THAT(events, HasSubstr("\"fault\":\"emcy\""));
  EXPECT_THAT(events, HasSubstr("\"fault\":\"dropout\""));
  EXPECT_THAT(events, HasSubstr("\"fault\":\"bus_off\""));
}

// The firmware's CANopen timers run on bus time in lockstep (docs/firmware.md, "Clocks"):
// faults_demo (cut to 3.25 s) with node 2's heartbeats lost for 1.5 s (1.0 .. 2.5 s), run once as
// it is and once with the firmware's host clock 8x slower (the emulator as the firmware would see
// it on a host 8x faster). The node is flagged lost (Status_NodeLostEnc2) from the same cycle and
// cleared at the same cycle, and can.log, events.jsonl and report.json (minus `wall`) are
// byte-identical. On the host clock it was flagged only when 3 s of bus time took more than 0.35 s
// of wall time (never in a Release build here: ~15 ms). The other direction (a slower host) is
// FwApp.FollowingSyncHeartbeatTimeoutIsJudgedOnBusTime: here a firmware clock 8x faster would
// turn a sanitizer build's ~1x real-time run into a bus without SYNC for 10 periods, i.e. the
// host-clock fallback.
TEST_F(ScenarioFaultsRun, HeartbeatTimeoutDoesNotDependOnTheHostSpeed) {
  const std::string path = std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/faults_demo.yaml";
  std::string text = Slurp(path);
  const std::string window = "node_id: 2, start_s: 1.0, end_s: 2.0}";
  ASSERT_NE(text.find(window), std::string::npos);
  text.replace(text.find(window), window.size(), "node_id: 2, start_s: 1.0, end_s: 2.5}");
  Scenario s = ParseScenario(text, path);
  testing::UseEmulatorSync(s);  // SYNC at the emulator's instants, whatever the firmware's clock
  s.expectations.clear();
  s.timing.duration_s = 3.25;
  const double period_s = s.timing.sync_period_s;
  (void)Run(s, "host1");
  s.firmware.command += " --clock-rate 0.125";
  (void)Run(s, "host8");
  const std::string log = Slurp(dir_ / "host1" / "can.log");
  EXPECT_EQ(log, Slurp(dir_ / "host8" / "can.log"));
  EXPECT_EQ(Slurp(dir_ / "host1" / "events.jsonl"), Slurp(dir_ / "host8" / "events.jsonl"));
  nlohmann::json ra = testing::ReportWithoutWall(dir_ / "host1");
  nlohmann::json rb = testing::ReportWithoutWall(dir_ / "host8");
  EXPECT_EQ(ra.dump(1), rb.dump(1));
  // FW_Status (0x686): byte 2 bit 1 Status_NodeLostEnc2, byte 7 Status_Cycle (cycle k opens at
  // SYNC k, motion time k x period).
  std::vector<int> lost;
  for (const LogFrame& f : ReadLog(dir_ / "host1" / "can.log")) {
    if (f.id != 0x686 || f.data.size() != 16) continue;
    if (std::stoi(f.data.substr(4, 2), nullptr, 16) & 0x02) {
      lost.push_back(std::stoi(f.data.substr(14, 2), nullptr, 16));
    }
  }
  ASSERT_FALSE(lost.empty());
  // Flagged once silent for more than heartbeat_timeout_s (0.35 s) of bus time, at most one
  // period + one heartbeat period (0.1 s) + one period later; cleared by the first heartbeat
  // after 2.5 s (within a period or two).
  const double first_s = lost.front() * period_s - 1.0;
  EXPECT_GE(first_s, 0.35 - 0.1);
  EXPECT_LE(first_s, 0.35 + 0.1 + 2 * period_s);
  EXPECT_GE(lost.back() * period_s, 2.5 - period_s);
  EXPECT_LE(lost.back() * period_s, 2.5 + 2 * period_s);
  EXPECT_EQ(lost.back() - lost.front() + 1, static_cast<int>(lost.size()));  // One stretch.
}

}  // namespace
}  // namespace wheelhil::emulator::scenario
