// The CiA 301 numbers of bus/canopen.h against the values the standard gives (and the project's
// golden traces use), and the COB-ID helpers at the edges of each function's id range. The EDS
// reader (bus/canopen_eds.h) against values outside their data type and paths that are not
// regular files.

#include "bus/canopen.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

#include "bus/canopen_eds.h"
#include "tests/bus/input_file_test_util.h"

namespace wheelhil::bus::canopen {
namespace {

static_assert(CobId(Function::kEmcy, 1) == 0x081);
static_assert(CobId(Function::kTpdo1, 3) == 0x183);
static_assert(CobId(Function::kSdoResponse, 127) == 0x5FF);
static_assert(CobId(Function::kSdoRequest, 1) == 0x601);
static_assert(CobId(Function::kErrorControl, 2) == 0x702);

TEST(CanopenCobId, FunctionCodesAreThePredefinedConnectionSet) {
  EXPECT_EQ(kNmtCobId, 0x000u);
  EXPECT_EQ(kSyncCobId, 0x080u);
  EXPECT_EQ(FunctionCode(Function::kEmcy), 0x080u);
  EXPECT_EQ(FunctionCode(Function::kTpdo1), 0x180u);
  EXPECT_EQ(FunctionCode(Function::kRpdo1), 0x200u);
  EXPECT_EQ(FunctionCode(Function::kTpdo2), 0x280u);
  EXPECT_EQ(FunctionCode(Function::kRpdo2), 0x300u);
  EXPECT_EQ(FunctionCode(Function::kTpdo3), 0x380u);
  EXPECT_EQ(FunctionCode(Function::kRpdo3), 0x400u);
  EXPECT_EQ(FunctionCode(Function::kTpdo4), 0x480u);
  EXPECT_EQ(FunctionCode(Function::kRpdo4), 0x500u);
  EXPECT_EQ(FunctionCode(Function::kSdoResponse), 0x580u);
  EXPECT_EQ(FunctionCode(Function::kSdoRequest), 0x600u);
  EXPECT_EQ(FunctionCode(Function::kErrorControl), 0x700u);
}

TEST(CanopenCobId, NodeAndFunctionSplitAnId) {
  EXPECT_EQ(NodeOf(0x77F), 127);
  EXPECT_EQ(NodeOf(kSyncCobId), 0);
  EXPECT_EQ(FunctionCodeOf(0x5A3), 0x580u);
  EXPECT_EQ(FunctionCodeOf(0x0FF), 0x080u);
}

TEST(CanopenCobId, IsNeedsANodeIdAndAnElevenBitId) {
  EXPECT_FALSE(IsEmcy(kSyncCobId));  // same function code, node 0: SYNC
  EXPECT_TRUE(IsEmcy(0x081));
  EXPECT_TRUE(IsEmcy(0x0FF));
  EXPECT_FALSE(IsTpdo1(0x180));
  EXPECT_TRUE(IsTpdo1(0x1FF));
  EXPECT_FALSE(IsSdoResponse(0x600));
  EXPECT_TRUE(IsSdoResponse(0x5FF));
  EXPECT_FALSE(IsSdoRequest(0x600));
  EXPECT_TRUE(IsSdoRequest(0x601));
  EXPECT_TRUE(IsSdoRequest(0x67F));
  EXPECT_FALSE(IsSdoRequest(0x680));
  EXPECT_TRUE(IsErrorControl(0x701));
  EXPECT_FALSE(IsErrorControl(0x700));
  EXPECT_FALSE(IsErrorControl(0x780));
  EXPECT_FALSE(IsErrorControl(0xF01));  // beyond 11 bits
}

TEST(CanopenCobId, ValidNodeIdsAreOneTo127) {
  EXPECT_FALSE(IsValidNodeId(0));
  EXPECT_TRUE(IsValidNodeId(1));
  EXPECT_TRUE(IsValidNodeId(127));
  EXPECT_FALSE(IsValidNodeId(128));
}

TEST(CanopenNmt, CommandSpecifiersAndStates) {
  EXPECT_EQ(nmt::kStart, 0x01);
  EXPECT_EQ(nmt::kStop, 0x02);
  EXPECT_EQ(nmt::kEnterPreOperational, 0x80);
  EXPECT_EQ(nmt::kResetNode, 0x81);
  EXPECT_EQ(nmt::kResetCommunication, 0x82);
  EXPECT_EQ(nmt_state::kBootUp, 0x00);
  EXPECT_EQ(nmt_state::kStopped, 0x04);
  EXPECT_EQ(nmt_state::kOperational, 0x05);
  EXPECT_EQ(nmt_state::kPreOperational, 0x7F);
}

TEST(CanopenSdo, CommandBytesOfTheExpeditedTransfers) {
  EXPECT_EQ(sdo::ExpeditedDownloadRequest(4), 0x23);
  EXPECT_EQ(sdo::ExpeditedDownloadRequest(3), 0x27);
  EXPECT_EQ(sdo::ExpeditedDownloadRequest(2), 0x2B);
  EXPECT_EQ(sdo::ExpeditedDownloadRequest(1), 0x2F);
  EXPECT_EQ(sdo::ExpeditedUploadResponse(4), 0x43);
  EXPECT_EQ(sdo::ExpeditedUploadResponse(1), 0x4F);
  EXPECT_EQ(sdo::kDownloadResponse, 0x60);
  EXPECT_EQ(sdo::kAbort, 0x80);
  EXPECT_EQ(sdo::CommandByte(sdo::kCcsInitiateUpload), 0x40);  // upload request
  for (std::uint8_t size = 1; size <= 4; ++size) {
    const std::uint8_t c = sdo::ExpeditedDownloadRequest(size);
    EXPECT_EQ(sdo::CommandSpecifier(c), sdo::kCcsInitiateDownload);
    EXPECT_EQ(sdo::ExpeditedSize(c), size);
    EXPECT_TRUE(c & sdo::kExpedited);
    EXPECT_TRUE(c & sdo::kSizeIndicated);
  }
  EXPECT_EQ(sdo::CommandSpecifier(sdo::kAbort), sdo::kCsAbort);
}

TEST(CanopenSdo, AbortCodesInUseHaveTheStandardValues) {
  EXPECT_EQ(sdo::kAbortCommand, 0x05040001u);
  EXPECT_EQ(sdo::kAbortReadOnly, 0x06010002u);
  EXPECT_EQ(sdo::kAbortNoObject, 0x06020000u);
  EXPECT_EQ(sdo::kAbortLength, 0x06070010u);
  EXPECT_EQ(sdo::kAbortNoSubindex, 0x06090011u);
  EXPECT_EQ(sdo::kAbortValue, 0x06090030u);
}

// --- EDS files --------------------------------------------------------------------------------

using ::testing::HasSubstr;
using ::testing::ThrowsMessage;

const std::string kEdsData = std::string(WHEELHIL_SOURCE_DIR) + "/tests/data/eds/";

// A value its DataType cannot hold used to be cut to the object's size when the node was built
// (a heartbeat of 70000 ms became 4464 ms); a sum beyond 64 bits was signed overflow.
TEST(EdsFile, ValuesOutsideTheirDataTypeAreRefusedNamingObjectAndRange) {
  const std::string heartbeat = kEdsData + "heartbeat_out_of_range.eds";
  EXPECT_THAT([&] { (void)EdsFile::LoadFile(heartbeat); },
              ThrowsMessage<std::invalid_argument>(
                  heartbeat + ":15: [1017] DefaultValue: '70000' is 70000, outside UNSIGNED16's "
                              "range 0..65535"));
  const std::string sum = kEdsData + "sum_beyond_64_bits.eds";
  EXPECT_THAT([&] { (void)EdsFile::LoadFile(sum); },
              ThrowsMessage<std::invalid_argument>(
                  sum + ":15: [2000] DefaultValue: '0xFFFFFFFFFFFFFFFF + 0x2' is "
                        "18446744073709551617, outside UNSIGNED64's range "
                        "0..18446744073709551615"));
  auto throws = [](const std::string& text, const std::string& what) {
    EXPECT_THAT([&] { (void)EdsFile::Parse(text, "bad.eds"); },
                ThrowsMessage<std::invalid_argument>(HasSubstr(what)))
        << text;
  };
  const std::string head = "[6001]\nAccessType=rw\n";
  throws(head + "DataType=0x0005\nDefaultValue=-1\n",
         "bad.eds:4: [6001] DefaultValue: '-1' is -1, outside UNSIGNED8's range 0..255");
  throws(head + "DataType=0x0002\nDefaultValue=-129\n", "outside INTEGER8's range -128..127");
  throws(head + "DataType=0x0001\nDefaultValue=2\n", "outside BOOLEAN's range 0..1");
  throws(head + "DataType=0x0016\nDefaultValue=0x1000000\n",
         "'0x1000000' is 16777216, outside UNSIGNED24's range 0..16777215");
  throws(head + "DataType=0x0015\nDefaultValue=0x7FFFFFFFFFFFFFFF+0x7FFFFFFFFFFFFFFF\n",
         "is 18446744073709551614, outside INTEGER64's range -9223372036854775808..");
  throws(head +
             "DataType=0x001B\nDefaultValue=0xFFFFFFFFFFFFFFFF+0xFFFFFFFFFFFFFFFF+"
             "0xFFFFFFFFFFFFFFFF+0xFFFFFFFFFFFFFFFF+0xFFFFFFFFFFFFFFFF\n",
         "is beyond 64 bits, outside UNSIGNED64's range");
  // A DCF's configured value is named as such.
  throws("[1017]\nDataType=0x0006\nAccessType=rw\nDefaultValue=100\nParameterValue=0x10000\n",
         "bad.eds:5: [1017] ParameterValue: '0x10000' is 65536, outside UNSIGNED16's range");
  // The edges fit.
  const EdsFile edges = EdsFile::Parse(
      "[6001]\nDataType=0x0002\nAccessType=ro\nDefaultValue=-128\n"
      "[6002]\nDataType=0x0015\nAccessType=ro\nDefaultValue=-0x8000000000000000\n"
      "[6003]\nDataType=0x001B\nAccessType=ro\nDefaultValue=0xFFFFFFFFFFFFFFFF\n"
      "[6004]\nDataType=0x0006\nAccessType=ro\nDefaultValue=0x10000-$NODEID\n",
      "edges.eds");
  EXPECT_EQ(edges.Integer(0x6001, 0, 1), static_cast<std::uint64_t>(-128));
  EXPECT_EQ(edges.Integer(0x6002, 0, 1), 0x8000000000000000u);
  EXPECT_EQ(edges.Integer(0x6003, 0, 1), 0xFFFFFFFFFFFFFFFFu);
  EXPECT_EQ(edges.Integer(0x6004, 0, 1), 0xFFFFu);
}

// A $NODEID value may fit with one node id and not another: checked with the node's own.
TEST(EdsFile, ANodeIdValueIsCheckedWithTheNodesId) {
  const std::string path = kEdsData + "nodeid_out_of_range.eds";
  const EdsFile eds = EdsFile::LoadFile(path);
  EXPECT_EQ(eds.Integer(0x1800, 5, 63), 0xFFFFu);
  EXPECT_THAT([&] { (void)eds.Integer(0x1800, 5, 64); },
              ThrowsMessage<std::invalid_argument>(
                  path + ":27: [1800sub5] DefaultValue: '$NODEID+0xFFC0' is 65536 with node id "
                         "64, outside UNSIGNED16's range 0..65535"));
}

// A FIFO hung the load, a directory read as an empty file, a byte-order mark was a syntax error.
TEST(EdsFile, OnlyRegularFilesOfAtMostTheLimitAndABomIsSkipped) {
  const testing::ScratchDir dir;
  auto error = [](const std::string& path) -> std::string {
    try {
      (void)EdsFile::LoadFile(path);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "(loaded without an error)";
  };
  const std::string fifo = dir.Fifo("fifo.eds");
  EXPECT_EQ(testing::LoadErrorOfFifo(fifo, [&] { (void)EdsFile::LoadFile(fifo); }),
            fifo + ":0: is not a regular file (a device or a pipe?)");
  EXPECT_EQ(error(dir.Path("")), dir.Path("") + ":0: is a directory, not an EDS file");
  EXPECT_EQ(error(dir.Path("none.eds")),
            dir.Path("none.eds") + ":0: cannot open EDS file (No such file or directory)");
  const std::string big = dir.Sparse("big.eds", EdsFile::kMaxFileBytes + 1);
  EXPECT_EQ(error(big), big +
                            ":0: is larger than 16 MiB, the limit for an EDS file; a device's "
                            "EDS is at most a few MiB");
  const EdsFile bom = EdsFile::LoadFile(kEdsData + "utf8_bom_encoder.eds");
  const EdsFile plain = EdsFile::LoadFile(std::string(WHEELHIL_SOURCE_DIR) +
                                          "/scenarios/own_hardware/encoder_cia406.eds");
  EXPECT_EQ(bom.entries().size(), plain.entries().size());
  EXPECT_EQ(bom.Integer(0x6001, 0, 5), plain.Integer(0x6001, 0, 5));
  EXPECT_EQ(bom.device_info().at("ProductName"), "Example incremental encoder");
}

}  // namespace
}  // namespace wheelhil::bus::canopen
