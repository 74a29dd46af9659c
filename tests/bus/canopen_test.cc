// The CiA 301 numbers of bus/canopen.h against the values the standard gives (and the project's
// golden traces use), and the COB-ID helpers at the edges of each function's id range.

#include "bus/canopen.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace wheelhil::bus::canopen
