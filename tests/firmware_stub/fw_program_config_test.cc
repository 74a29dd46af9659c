// Config errors of the firmware program (file:line:col: field: problem) and the shipped
// scenarios/firmware/*.yaml files.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <optional>
#include <fstream>

#include "firmware_stub/drive_protocol.h"
#include "firmware_stub/fw_app.h"
#include "firmware_stub/fw_config.h"
#include "firmware_stub/fw_protocol.h"
#include "tests/firmware_stub/fw_test_devices.h"

namespace wheelhil::fw {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

const char* kOk = R"(estimator: paper000
sync: {period_s: 0.25}
imu: {yaw_frame_id: 0x174}
paper000:
  track_width_m: 0.5
  wheel_radius_m: 0.075
  counts_per_rev: 2000
  left: {node_id: 1}
  right: {node_id: 2, sign: -1}
  calibration_samples: 40
)";

std::string Replace(std::string s, const std::string& from, const std::string& to) {
  const auto at = s.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  return s.replace(at, from.size(), to);
}

void ExpectError(const std::string& yaml, const std::string& message) {
  EXPECT_THAT([&] { ParseFwConfig(yaml, "fw.yaml"); },
              ThrowsMessage<std::invalid_argument>(HasSubstr(message)));
}

TEST(FwProgramConfig, ReadsEverySection) {
  const FwConfig c = ParseFwConfig(kOk, "/cfg/fw.yaml");
  EXPECT_EQ(c.estimator, EstimatorKind::kPaper000SlipCorrection);
  EXPECT_DOUBLE_EQ(c.sync.period_s, 0.25);
  EXPECT_DOUBLE_EQ(c.sync.deadline_s, 0.225);  // Default 0.9 period.
  EXPECT_TRUE(c.sync.produce);
  EXPECT_TRUE(c.imu.enabled);
  EXPECT_EQ(c.imu.yaw_frame_id, 0x174u);
  EXPECT_FALSE(c.accel.enabled);
  EXPECT_EQ(c.paper000.right.sign, -1);
  EXPECT_EQ(c.paper000.calibration_samples, 40);
  EXPECT_EQ(c.canopen.tpdo_transmission_type, 1);
  ASSERT_EQ(c.encoder_nodes().size(), 2u);
  EXPECT_EQ(c.encoder_nodes()[1].node_id, 2);
  EXPECT_TRUE(c.dbc_dir.empty());
  EXPECT_EQ(ParseFwConfig(std::string(kOk) + "dbc_dir: ../dbc\n", "/cfg/sub/fw.yaml").dbc_dir,
            "/cfg/dbc");
}

TEST(FwProgramConfig, ErrorsNameFileLineAndField) {
  ExpectError(Replace(kOk, "track_width_m: 0.5", "track_width_m: -0.5"),
              "fw.yaml:5:18: paper000.track_width_m: (-0.5) must be > 0");
  ExpectError(Replace(kOk, "{period_s: 0.25}", "{period_s: 0.25, deadline_s: -1}"),
              "sync.deadline_s: (-1) must be >= 0");
  ExpectError(Replace(kOk, "track_width_m: 0.5", "trackwidth_m: 0.5"),
              "fw.yaml:5:3: paper000.trackwidth_m: unknown key");
  ExpectError(Replace(kOk, "counts_per_rev: 2000", "counts_per_rev: lots"),
              "fw.yaml:7:19: paper000.counts_per_rev: 'lots' is not a number");
  ExpectError(Replace(kOk, "{node_id: 2, sign: -1}", "{node_id: 200}"),
              "fw.yaml:9:20: paper000.right.node_id: (200) must be in [1, 127]");
  ExpectError(Replace(kOk, "{node_id: 2, sign: -1}", "{node_id: 1}"),
              "paper000: node_id 1 is used twice");
  ExpectError(Replace(kOk, "{period_s: 0.25}", "{period_s: 0.25, deadline_s: 0.3}"),
              "fw.yaml:2:36: sync.deadline_s: (0.3) must be <= period_s (0.25)");
  ExpectError(Replace(kOk, "sync: {period_s: 0.25}\n", ""), "fw.yaml:1:1: sync: is required");
  ExpectError(Replace(kOk, "imu: {yaw_frame_id: 0x174}\n", ""),
              "imu: paper000 needs the yaw-rate IMU");
  ExpectError(Replace(kOk, "calibration_samples: 40", "calibration_samples: 0"),
              "fw.yaml:5:3: paper000.residual_sigma_rad: is required");
  ExpectError(Replace(kOk, "0x174", "0x900"), "imu.yaw_frame_id: (2304) must be in [1, 2047]");
  ExpectError(Replace(kOk, "estimator: paper000", "estimator: paper999"),
              "fw.yaml:1:12: estimator: 'paper999' is not one of");
  ExpectError("estimator: paper000\nsync: {period_s: [1\n", "fw.yaml:");
  ExpectError(std::string(kOk) + "canopen: {heartbeat_period_s: 0.5, heartbeat_timeout_s: 0.2}\n",
              "canopen.heartbeat_timeout_s: (0.2) must exceed heartbeat_period_s (0.5)");
  ExpectError(std::string(kOk) + "canopen: {tpdo_transmission_type: 254}\n",
              "canopen.tpdo_transmission_type: (254) must be in [0, 240]");
}

TEST(FwProgramConfig, Paper001And002NeedThreeWheels) {
  const std::string p2 = R"(estimator: paper002
sync: {period_s: 0.001}
accel: {frame_id: 0x170}
paper002:
  wheel_radius_m: 0.05
  wheel_mount_radius_m: 0.2
  counts_per_rev: 4096
  accel_mount_radius_m: 0.15
  wheels:
    - {node_id: 1, angle_deg: 0}
    - {node_id: 2, angle_deg: 120}
)";
  ExpectError(p2, "fw.yaml:10:5: paper002.wheels: must be a list of exactly three entries");
  ExpectError(p2 + "    - {node_id: 3}\n",
              "fw.yaml:12:7: paper002.wheels[2].angle_deg: is required");
  const FwConfig c = ParseFwConfig(p2 + "    - {node_id: 3, angle_deg: 240}\n", "fw.yaml");
  EXPECT_NEAR(c.paper002.angles_rad[2], 4.18879, 1e-5);
  EXPECT_EQ(c.accel.frame_id, 0x170u);
}

TEST(FwProgramConfig, ShippedScenarioConfigsLoadAndBind) {
  const auto dir = std::filesystem::path(WHEELHIL_SOURCE_DIR) / "scenarios" / "firmware";
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    if (e.path().extension() != ".yaml") continue;
    SCOPED_TRACE(e.path().string());
    const FwConfig c = LoadFwConfig(e.path().string());
    std::vector<int> ids;
    for (const auto& node : c.encoder_nodes()) ids.push_back(node.node_id);
    const FwProtocol p =
        FwProtocol::LoadDir(testing::DbcDir(), ids, c.imu.enabled ? c.imu.yaw_frame_id : 0,
                            c.accel.enabled ? c.accel.frame_id : 0);
    EXPECT_TRUE(p.unbound_output_signals().empty());
    std::optional<DriveProtocol> drives;
    if (c.drives.enabled) {
      std::vector<int> drive_ids;
      for (const auto& d : c.drives.nodes) drive_ids.push_back(d.node_id);
      drives.emplace(DriveProtocol::LoadDir(testing::DbcDir(), drive_ids));
    }
    FwApp app(c, p, drives ? &*drives : nullptr);
    ++n;
  }
  EXPECT_EQ(n, 5);
}

TEST(FwProgramConfig, ProtocolBindsEveryOutputSignalOfTheDbc) {
  const FwProtocol p = FwProtocol::LoadDir(testing::DbcDir(), {1, 2}, 0x174, 0x170);
  EXPECT_THAT(p.unbound_output_signals(), ::testing::IsEmpty());
  EXPECT_THAT(
      p.OutputFields(OutMessage::kStatus),
      ::testing::IsSupersetOf(
          {OutField::kHeartbeat, OutField::kState, OutField::kFaultEmcy, OutField::kFaultBadFrame,
           OutField::kFaultConfig, OutField::kNodeLostEnc1, OutField::kNodeLostEnc8,
           OutField::kNodeLostImu, OutField::kNodeLostAccel, OutField::kEmcyNodeId,
           OutField::kBadFrameCount, OutField::kCycle, OutField::kFaultSdo,
           OutField::kFaultBootTimeout, OutField::kFaultCycleIncomplete, OutField::kFaultLateFrame,
           OutField::kFaultEstimator}));
  EXPECT_THAT(p.OutputFields(OutMessage::kSlipStatus),
              ::testing::UnorderedElementsAre(
                  OutField::kCycle, OutField::kSlipLeft, OutField::kSlipRight, OutField::kOutOfBand,
                  OutField::kSlipUnattributed, OutField::kCalibrated, OutField::kResidual,
                  OutField::kBandLow, OutField::kBandHigh));
  for (OutMessage m : {OutMessage::kPose, OutMessage::kPoseRaw}) {
    EXPECT_THAT(p.OutputFields(m), ::testing::UnorderedElementsAre(OutField::kCycle, OutField::kX,
                                                                   OutField::kY, OutField::kTheta));
  }
}

TEST(FwProgramConfig, MissingDbcFileOrMessageIsNamed) {
  EXPECT_THAT([] { FwProtocol::LoadDir("/nonexistent", {1}, 0, 0); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("/nonexistent/cia406_encoder.dbc: DBC file not found")));
  EXPECT_THAT([] { FwProtocol::LoadDir(testing::DbcDir(), {1}, 0x175, 0); },
              ThrowsMessage<std::invalid_argument>(
                  HasSubstr("bosch_mm5_10.dbc: no message with id 0x175 (imu.yaw_frame_id)")));
  EXPECT_THAT([] { FwProtocol::LoadDir(testing::DbcDir(), {1}, 0, 0x174); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("wheelhil_accel4.dbc")));
}

}  // namespace
}  // namespace wheelhil::fw
