#pragma once
/// CiA 301 definitions shared by every CANopen implementation in wheelhil: the emulator's
/// devices (slaves) and the firmware's master both take their identifiers, command bytes and
/// abort codes from here, so the two can never disagree on a number. Values and constexpr
/// helpers only: no state, no frames, no I/O; the master and the slave stay separate code.
///
/// COB-IDs follow the pre-defined connection set: 11-bit identifier = function code (bits 10..7)
/// + node id (bits 6..0, 1..127). NMT (0x000) and SYNC (0x080) carry no node id; EMCY shares
/// SYNC's function code and is told apart by a node id != 0. "Request" and "response" name the
/// SDO direction from the client's side: request = client -> server (0x600 + id), response =
/// server -> client (0x580 + id).

#include <cstdint>

namespace wheelhil::bus::canopen {

inline constexpr std::uint32_t kNmtCobId = 0x000;   ///< NMT module control [cs, node].
inline constexpr std::uint32_t kSyncCobId = 0x080;  ///< SYNC (no counter here: length 0).

inline constexpr std::uint8_t kMaxNodeId = 127;
inline constexpr std::uint32_t kNodeIdMask = 0x07F;
inline constexpr std::uint32_t kFunctionMask = 0x780;

/// Function codes of a node's own communication objects (COB-ID = code + node id).
enum class Function : std::uint32_t {
  kEmcy = 0x080,
  kTpdo1 = 0x180,
  kRpdo1 = 0x200,
  kTpdo2 = 0x280,
  kRpdo2 = 0x300,
  kTpdo3 = 0x380,
  kRpdo3 = 0x400,
  kTpdo4 = 0x480,
  kRpdo4 = 0x500,
  kSdoResponse = 0x580,   ///< Server (node) -> client.
  kSdoRequest = 0x600,    ///< Client -> server (node).
  kErrorControl = 0x700,  ///< Boot-up (state byte 0x00) and heartbeat.
};

constexpr std::uint32_t FunctionCode(Function f) { return static_cast<std::uint32_t>(f); }

constexpr bool IsValidNodeId(unsigned node_id) { return node_id >= 1 && node_id <= kMaxNodeId; }

/// The COB-ID of `f` for `node_id` (1..127).
constexpr std::uint32_t CobId(Function f, std::uint8_t node_id) {
  return FunctionCode(f) + node_id;
}

/// Node id bits of an 11-bit COB-ID (0 for NMT and SYNC).
constexpr std::uint8_t NodeOf(std::uint32_t cob_id) {
  return static_cast<std::uint8_t>(cob_id & kNodeIdMask);
}

/// Function code bits of an 11-bit COB-ID.
constexpr std::uint32_t FunctionCodeOf(std::uint32_t cob_id) { return cob_id & kFunctionMask; }

/// True when `cob_id` is function `f` of some node 1..127.
constexpr bool Is(Function f, std::uint32_t cob_id) {
  return cob_id <= 0x7FF && FunctionCodeOf(cob_id) == FunctionCode(f) && NodeOf(cob_id) != 0;
}
constexpr bool IsEmcy(std::uint32_t cob_id) { return Is(Function::kEmcy, cob_id); }
constexpr bool IsTpdo1(std::uint32_t cob_id) { return Is(Function::kTpdo1, cob_id); }
constexpr bool IsSdoResponse(std::uint32_t cob_id) { return Is(Function::kSdoResponse, cob_id); }
constexpr bool IsSdoRequest(std::uint32_t cob_id) { return Is(Function::kSdoRequest, cob_id); }
constexpr bool IsErrorControl(std::uint32_t cob_id) { return Is(Function::kErrorControl, cob_id); }

/// NMT module control command specifiers (byte 0 of a kNmtCobId frame; byte 1 = node, 0 = all).
namespace nmt {
inline constexpr std::uint8_t kStart = 0x01;
inline constexpr std::uint8_t kStop = 0x02;
inline constexpr std::uint8_t kEnterPreOperational = 0x80;
inline constexpr std::uint8_t kResetNode = 0x81;
inline constexpr std::uint8_t kResetCommunication = 0x82;
}  // namespace nmt

/// NMT states as the error-control frame reports them (its one data byte).
namespace nmt_state {
inline constexpr std::uint8_t kBootUp = 0x00;
inline constexpr std::uint8_t kStopped = 0x04;
inline constexpr std::uint8_t kOperational = 0x05;
inline constexpr std::uint8_t kPreOperational = 0x7F;
}  // namespace nmt_state

/// PDO communication parameter COB-ID entry (0x1800+n sub 1) flag bits.
inline constexpr std::uint32_t kPdoCobIdInvalid = 1u << 31;   ///< PDO does not exist / disabled.
inline constexpr std::uint32_t kPdoCobIdNoRtr = 1u << 30;     ///< No RTR allowed on this PDO.
inline constexpr std::uint32_t kPdoCobIdExtended = 1u << 29;  ///< 29-bit CAN identifier.

/// Object dictionary entries of the communication profile that both sides use.
namespace od {
inline constexpr std::uint16_t kDeviceType = 0x1000;
inline constexpr std::uint16_t kErrorRegister = 0x1001;
/// Consumer heartbeat time, sub 1..n: u32, node id << 16 | time in ms (0 = off).
inline constexpr std::uint16_t kConsumerHeartbeatTime = 0x1016;
inline constexpr std::uint16_t kProducerHeartbeatTime = 0x1017;  ///< u16, ms; 0 = off.
inline constexpr std::uint16_t kIdentity = 0x1018;
inline constexpr std::uint16_t kTpdo1Communication = 0x1800;
inline constexpr std::uint16_t kTpdo1Mapping = 0x1A00;
/// Sub-indices of a PDO communication parameter record (0x1400.., 0x1800..).
inline constexpr std::uint8_t kPdoCobId = 1;
inline constexpr std::uint8_t kPdoTransmissionType = 2;
inline constexpr std::uint8_t kPdoEventTimer = 5;
}  // namespace od

/// EMCY: error code 0x0000 is the error reset; error register (0x1001) bit 0 is generic error.
inline constexpr std::uint16_t kEmcyErrorReset = 0x0000;
inline constexpr std::uint8_t kErrorRegisterGeneric = 0x01;

/// SDO command byte (byte 0): command specifier in bits 7..5; for an initiate transfer n (bits
/// 3..2, unused data bytes when e = s = 1), e (bit 1, expedited), s (bit 0, size indicated).
namespace sdo {
// Client command specifiers (request, client -> server).
inline constexpr std::uint8_t kCcsDownloadSegment = 0;
inline constexpr std::uint8_t kCcsInitiateDownload = 1;
inline constexpr std::uint8_t kCcsInitiateUpload = 2;
inline constexpr std::uint8_t kCcsUploadSegment = 3;
inline constexpr std::uint8_t kCcsBlockUpload = 5;
inline constexpr std::uint8_t kCcsBlockDownload = 6;
// Server command specifiers (response, server -> client).
inline constexpr std::uint8_t kScsUploadSegment = 0;
inline constexpr std::uint8_t kScsDownloadSegment = 1;
inline constexpr std::uint8_t kScsInitiateUpload = 2;
inline constexpr std::uint8_t kScsInitiateDownload = 3;
inline constexpr std::uint8_t kScsBlockDownload = 5;
inline constexpr std::uint8_t kScsBlockUpload = 6;
/// Abort transfer, the same specifier in both directions.
inline constexpr std::uint8_t kCsAbort = 4;

inline constexpr std::uint8_t kSizeIndicated = 0x01;  ///< s
inline constexpr std::uint8_t kExpedited = 0x02;      ///< e

constexpr std::uint8_t CommandSpecifier(std::uint8_t command) {
  return static_cast<std::uint8_t>(command >> 5);
}
/// The command byte of a specifier with every other bit clear.
constexpr std::uint8_t CommandByte(std::uint8_t specifier) {
  return static_cast<std::uint8_t>(specifier << 5);
}
/// Data bytes of an expedited transfer with size indicated (4 - n).
constexpr std::uint8_t ExpeditedSize(std::uint8_t command) {
  return static_cast<std::uint8_t>(4 - ((command >> 2) & 3));
}
/// Initiate command byte of an expedited transfer of `size` (1..4) bytes, size indicated.
constexpr std::uint8_t ExpeditedCommand(std::uint8_t specifier, std::uint8_t size) {
  return static_cast<std::uint8_t>(CommandByte(specifier) | ((4 - size) << 2) | kExpedited |
                                   kSizeIndicated);
}

/// Client: expedited download request of `size` bytes (0x23, 0x27, 0x2B, 0x2F for 4..1).
constexpr std::uint8_t ExpeditedDownloadRequest(std::uint8_t size) {
  return ExpeditedCommand(kCcsInitiateDownload, size);
}
/// Server: expedited upload response of `size` bytes (0x43, 0x47, 0x4B, 0x4F for 4..1).
constexpr std::uint8_t ExpeditedUploadResponse(std::uint8_t size) {
  return ExpeditedCommand(kScsInitiateUpload, size);
}
/// Server: initiate download response (0x60).
inline constexpr std::uint8_t kDownloadResponse = CommandByte(kScsInitiateDownload);
/// Abort transfer (0x80); bytes 4..7 carry the abort code.
inline constexpr std::uint8_t kAbort = CommandByte(kCsAbort);

// Abort codes (CiA 301, SDO abort transfer).
inline constexpr std::uint32_t kAbortToggleBit = 0x05030000;  ///< Toggle bit not alternated.
inline constexpr std::uint32_t kAbortTimeout = 0x05040000;    ///< SDO protocol timed out.
inline constexpr std::uint32_t kAbortCommand = 0x05040001;    ///< Command specifier unknown.
inline constexpr std::uint32_t kAbortBlockSize = 0x05040002;
inline constexpr std::uint32_t kAbortSequenceNumber = 0x05040003;
inline constexpr std::uint32_t kAbortCrc = 0x05040004;
inline constexpr std::uint32_t kAbortOutOfMemory = 0x05040005;
inline constexpr std::uint32_t kAbortUnsupportedAccess = 0x06010000;
inline constexpr std::uint32_t kAbortWriteOnly = 0x06010001;  ///< Read of a write-only object.
inline constexpr std::uint32_t kAbortReadOnly = 0x06010002;   ///< Write to a read-only object.
inline constexpr std::uint32_t kAbortNoObject = 0x06020000;   ///< Not in the dictionary.
inline constexpr std::uint32_t kAbortNotMappable = 0x06040041;
inline constexpr std::uint32_t kAbortPdoLength = 0x06040042;  ///< Mapping exceeds PDO length.
inline constexpr std::uint32_t kAbortParameterIncompatible = 0x06040043;
inline constexpr std::uint32_t kAbortInternalIncompatible = 0x06040047;
inline constexpr std::uint32_t kAbortHardware = 0x06060000;
inline constexpr std::uint32_t kAbortLength = 0x06070010;  ///< Data length does not match.
inline constexpr std::uint32_t kAbortLengthTooHigh = 0x06070012;
inline constexpr std::uint32_t kAbortLengthTooLow = 0x06070013;
inline constexpr std::uint32_t kAbortNoSubindex = 0x06090011;
inline constexpr std::uint32_t kAbortValue = 0x06090030;  ///< Invalid value (download only).
inline constexpr std::uint32_t kAbortValueTooHigh = 0x06090031;
inline constexpr std::uint32_t kAbortValueTooLow = 0x06090032;
inline constexpr std::uint32_t kAbortMaxBelowMin = 0x06090036;
inline constexpr std::uint32_t kAbortNoConnection = 0x060A0023;  ///< No SDO connection free.
inline constexpr std::uint32_t kAbortGeneral = 0x08000000;
inline constexpr std::uint32_t kAbortNotStored = 0x08000020;
inline constexpr std::uint32_t kAbortNotStoredLocalControl = 0x08000021;
inline constexpr std::uint32_t kAbortNotStoredDeviceState = 0x08000022;
inline constexpr std::uint32_t kAbortNoDictionary = 0x08000023;
inline constexpr std::uint32_t kAbortNoData = 0x08000024;
}  // namespace sdo

}  // namespace wheelhil::bus::canopen
