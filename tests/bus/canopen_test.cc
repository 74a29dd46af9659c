// The CiA 301 numbers of bus/canopen.h against the values the standard gives (and the project's
// golden traces use), and the COB-ID helpers at the edges of each function's id range. The EDS
// reader (bus/canopen_eds.h) against paths that are not regular files.

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
