// CANopen device descriptions (bus/canopen_eds.h) and the CiA 406 node built from one
// (emulator/devices/cia406_eds.h): the shipped example EDS parses with its $NODEID expressions;
// the EDS-built encoder answers SDO uploads with the EDS's values and keeps what the master
// writes to its writable objects; what the node cannot be, or a file that does not parse, is an
// error naming the file, line and object.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>

#include "bus/candump_log.h"
#include "bus/canopen_eds.h"
#include "emulator/devices/canopen_encoder_node.h"
#include "emulator/devices/cia406_eds.h"
#include "emulator/devices/dbc_cia406_codec.h"

namespace wheelhil::emulator {
namespace {

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

const std::string kEds =
    std::string(WHEELHIL_SOURCE_DIR) + "/scenarios/own_hardware/encoder_cia406.eds";

bus::CanFrame Frame(const std::string& text) {
  bus::CanFrame f;
  std::string error;
  if (!bus::ParseCanUtilsFrame(text, f, &error)) ADD_FAILURE() << text << ": " << error;
  return f;
}

std::string Text(const bus::CanFrame& f) {
  const std::string line = bus::FormatCandumpLine(0, "x", f);
  return line.substr(line.rfind(' ') + 1);
}

TEST(EdsFile, TheExampleParsesWithItsNodeIdExpressions) {
  const bus::EdsFile eds = bus::EdsFile::LoadFile(kEds);
  EXPECT_EQ(eds.device_info().at("ProductName"), "Example incremental encoder");
  EXPECT_EQ(eds.Integer(0x1800, 1, 5), 0x185u);  // $NODEID+0x180
  EXPECT_EQ(eds.Integer(0x6001, 0, 5), 2000u);
  EXPECT_EQ(eds.Integer(0x1000, 0, 5), 0x00020196u);
  ASSERT_NE(eds.Find(0x2000, 0), nullptr);
  EXPECT_TRUE(eds.Find(0x2000, 0)->writable());
  EXPECT_EQ(eds.Find(0x1008, 0)->data_type, 0x0009);  // a string: kept, not an integer
  EXPECT_EQ(eds.Find(0x1018, 0)->default_value, "4");
  EXPECT_FALSE(eds.node_id());
}

TEST(EdsFile, ADcfGivesItsNodeIdAndParameterValues) {
  const bus::EdsFile dcf = bus::EdsFile::Parse(
      "[DeviceComissioning]\nNodeID=0x0C\n[1017]\nObjectType=0x7\nDataType=0x0006\n"
      "AccessType=rw\nDefaultValue=100\nParameterValue=250\n[2001]\nDataType=0x0007\n"
      "AccessType=ro\nDefaultValue=0x100 + $NODEID - 2\n",
      "enc.dcf");
  EXPECT_EQ(dcf.node_id(), 12);
  EXPECT_EQ(dcf.Integer(0x1017, 0, 12), 250u);
  EXPECT_EQ(dcf.Integer(0x2001, 0, 12), 0x10Au);
}

TEST(EdsFile, ErrorsNameTheFileLineAndObject) {
  auto throws = [](const std::string& text, const std::string& what) {
    EXPECT_THAT([&] { (void)bus::EdsFile::Parse(text, "bad.eds"); },
                ThrowsMessage<std::invalid_argument>(HasSubstr(what)))
        << text;
  };
  throws("[OptionalObjects]\nSupportedObjects=1\n1=0x6001\n",
         "bad.eds:3: [optionalobjects] 1: object 0x6001 has no section [6001]");
  throws("[6001]\nDataType=0x0007\nAccessType=readonly\n",
         "bad.eds:3: [6001] AccessType: 'readonly' is not one of ro");
  throws("[6001]\nDataType=0x0007\nAccessType=ro\nDefaultValue=2k\n",
         "bad.eds:4: [6001] DefaultValue: '2k' is not an integer");
  throws("[6001]\nAccessType=ro\n", "bad.eds:1: [6001] DataType: is required");
  throws("[1003]\nObjectType=0x8\nCompactSubObj=254\n", "CompactSubObj is not supported");
  throws("[6001]\nDataType=0x0007\n[6001]\n", "bad.eds:3: [6001] appears twice (first at line 1)");
  throws("DataType=1\n", "bad.eds:1: a key before the first [section]");
}

Cia406NodeConfig NodeFromEds(int node_id) {
  Cia406NodeConfig node;
  node.node_id = static_cast<std::uint8_t>(node_id);
  node.power_on_delay_ns = 0;
  (void)ApplyCia406Eds(bus::EdsFile::LoadFile(kEds), node);
  return node;
}

// The SDO answer of `node` to `request` (after its boot-up).
std::string Sdo(CanopenEncoderNode& node, const std::string& request,
                std::int64_t t_ns = 1'000'000) {
  const auto out = node.OnFrame(Frame(request), t_ns);
  return out.empty() ? std::string("(none)") : Text(out.back().frame);
}

TEST(Cia406Eds, TheEncoderAnswersSdoUploadsWithTheEdsValues) {
  Cia406NodeConfig config = NodeFromEds(3);
  SetCia406Object(config, 0x1018, 4, 40603);
  EXPECT_EQ(config.heartbeat_ms, 100);
  EXPECT_EQ(config.vendor_id, 0xABCu);
  const auto codec = DbcCia406Codec::FromFile(std::string(WHEELHIL_SOURCE_DIR) +
                                              "/bus/dbc/cia406_encoder.dbc");
  CanopenEncoderNode node(config, codec);
  (void)node.Poll(0);  // boot-up
  EXPECT_EQ(Sdo(node, "603#4001600000000000"), "583#43016000D0070000");  // 0x6001 = 2000
  EXPECT_EQ(Sdo(node, "603#4002600000000000"), "583#43026000FFFFFFFF");  // 0x6002
  EXPECT_EQ(Sdo(node, "603#4018100400000000"), "583#431810049B9E0000");  // serial 40603
  EXPECT_EQ(Sdo(node, "603#4018100200000000"), "583#4318100206040000");  // product 0x406
  EXPECT_EQ(Sdo(node, "603#4017100000000000"), "583#4B17100064000000");  // heartbeat 100
  EXPECT_EQ(Sdo(node, "603#4000200000000000"), "583#4B00200008000000");  // 0x2000 = 8
  // The writable manufacturer object keeps what the master writes, the read-only one refuses.
  EXPECT_EQ(Sdo(node, "603#2B00200010000000"), "583#6000200000000000");
  EXPECT_EQ(Sdo(node, "603#4000200000000000"), "583#4B00200010000000");
  EXPECT_EQ(Sdo(node, "603#2301600001000000"), "583#8001600002000106");  // read-only
  EXPECT_EQ(Sdo(node, "603#2F00200001000000"), "583#8000200010000706");  // wrong length
  EXPECT_EQ(Sdo(node, "603#4000200100000000"), "583#8000200111000906");  // no such sub
  EXPECT_EQ(Sdo(node, "603#4008100000000000"), "583#8008100000000206");  // long string: none
  // A reset of the application area restores the EDS value.
  (void)node.OnFrame(Frame("000#8103"), 2'000'000);
  (void)node.Poll(100'000'000);
  EXPECT_EQ(Sdo(node, "603#4000200000000000", 200'000'000), "583#4B00200008000000");
}

TEST(Cia406Eds, WhatTheNodeCannotBeIsRefused) {
  Cia406NodeConfig node;
  node.node_id = 2;
  EXPECT_THAT(
      [&] {
        (void)ApplyCia406Eds(
            bus::EdsFile::Parse("[1A00sub1]\nDataType=0x0007\nAccessType=ro\n"
                                "DefaultValue=0x60040010\n",
                                "m.eds"),
            node);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr(
          "m.eds:1: [1A00sub1] TPDO1 mapping 0x60040010: this node maps 0x6004 (position)")));
  EXPECT_THAT(
      [&] {
        (void)ApplyCia406Eds(bus::EdsFile::Parse("[DeviceComissioning]\nNodeID=5\n", "n.dcf"),
                             node);
      },
      ThrowsMessage<std::invalid_argument>(HasSubstr("the DCF is for node 5, the device is node 2")));
  EXPECT_THAT([&] { SetCia406Object(node, 0x2100, 0, 1); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("object 0x2100 sub 0 is not")));
}

}  // namespace
}  // namespace wheelhil::emulator
