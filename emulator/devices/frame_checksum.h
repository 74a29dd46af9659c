#pragma once
/// Rolling-counter and checksum helpers for DBC-defined frames (accelerometer node, generic DBC
/// IMU node, the wrong-counter / wrong-checksum frame faults). The checksum is computed over the
/// whole payload (msg.length bytes, or the frame's len if shorter) with the checksum signal's bits
/// set to zero:
///   kXor           XOR of all w-bit chunks of the payload, w = checksum width (4: nibbles, low
///                  nibble first, 8: bytes) - bus/dbc/wheelhil_accel4.dbc's ACC4_Checksum;
///   kSum           sum of the bytes modulo 2^w (w = 1..8);
///   kCrc8SaeJ1850  CRC-8 SAE J1850 (poly 0x1D, init 0xFF, final XOR 0xFF, no reflection) over
///                  the bytes; w must be 8;
///   kCrc8H2F       AUTOSAR's CRC-8H2F (poly 0x2F, init 0xFF, final XOR 0xFF); w = 8;
///   kCrc16Ccitt    CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no final XOR); w = 16.
/// The AUTOSAR E2E profiles for CAN put the CRC in a whole byte k (the signal: 8 bits, on a byte
/// boundary) and the 4-bit counter in the low nibble of byte k+1; their CRC leaves byte k out:
///   kE2eP11        CRC-8 SAE J1850 polynomial, start 0x00, no final XOR, over the data id's low
///                  byte, its high byte (0x00 in nibble mode, where the high nibble of byte k+1
///                  carries the id's bits 8..11), then the payload without byte k;
///   kE2eP22        CRC-8H2F over the payload without byte k, then DataIDList[counter].
/// Stateless, noexcept, no allocation; thread-safe.

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "bus/dbc.h"

namespace wheelhil::emulator {

enum class ChecksumKind : std::uint8_t {
  kXor, kSum, kCrc8SaeJ1850, kCrc8H2F, kCrc16Ccitt, kE2eP11, kE2eP22,
  kCrcCustom,  ///< ChecksumSpec::crc (any CRC of 1..32 bits), over the zeroed payload.
};

/// A CRC of up to 32 bits in the Rocksoft model (as catalogued by reveng): width, polynomial
/// (without its top bit), initial register, input/output reflection, final XOR.
struct CrcParams {
  int width = 8;
  std::uint32_t poly = 0;
  std::uint32_t init = 0;
  bool reflect_in = false;
  bool reflect_out = false;
  std::uint32_t xor_out = 0;
};
/// A kind with what the E2E profiles need besides the payload.
struct ChecksumSpec {
  ChecksumKind kind = ChecksumKind::kXor;
  std::uint16_t data_id = 0;            ///< kE2eP11.
  bool data_id_nibble = false;          ///< kE2eP11: DataIDMode NIBBLE (else BOTH).
  std::array<std::uint8_t, 16> data_id_list{};  ///< kE2eP22: by counter value.
  CrcParams crc;                                ///< kCrcCustom.
};

/// "xor", "sum", "crc8_sae_j1850" (also "crc8"), "crc8_h2f", "crc16_ccitt", "e2e_p11",
/// "e2e_p22", "crc" (kCrcCustom); nullopt for anything else.
std::optional<ChecksumKind> ParseChecksumKind(std::string_view name) noexcept;
std::string_view ChecksumKindName(ChecksumKind kind) noexcept;
/// The accepted names, for messages: "xor, sum, crc8_sae_j1850, crc8_h2f, crc16_ccitt, ...".
std::string_view ChecksumKindNames() noexcept;

inline constexpr CrcParams kCrc8SaeJ1850Params{8, 0x1D, 0xFF, false, false, 0xFF};
inline constexpr CrcParams kCrc8H2FParams{8, 0x2F, 0xFF, false, false, 0xFF};
inline constexpr CrcParams kCrc16CcittFalseParams{16, 0x1021, 0xFFFF, false, false, 0x0000};
/// Why `spec` cannot be carried by `sig` in `msg` (empty: it can): width, byte boundary, the
/// E2E counter byte inside the message.
std::string WhyChecksumDoesNotFit(const ChecksumSpec& spec, const bus::DbcSignal& sig,
                                  const bus::DbcMessage& msg);
/// The CRC of `bytes`, bit by bit (frames are at most 64 bytes).
std::uint32_t Crc(const CrcParams& p, std::span<const std::uint8_t> bytes) noexcept;

/// True when `kind` can be carried by `sig` (integer signal; width 4 or 8 for XOR, 1..8 for sum,
/// 8 for CRC-8).
bool ChecksumFits(ChecksumKind kind, const bus::DbcSignal& sig) noexcept;

/// CRC-8 SAE J1850 of the bytes (poly 0x1D, init 0xFF, xorout 0xFF); "123456789" -> 0x4B.
std::uint8_t Crc8SaeJ1850(std::span<const std::uint8_t> bytes) noexcept;

/// The checksum value for `payload` (checksum bits treated as zero; payload not modified).
/// Returns 0 when the payload is too short for the signal or longer than 64 bytes.
std::uint64_t ComputeChecksum(ChecksumKind kind, const bus::DbcSignal& checksum_sig,
                              std::span<const std::uint8_t> payload) noexcept;

/// Computes and inserts the checksum. False when the payload is too short for the signal.
bool WriteChecksum(ChecksumKind kind, const bus::DbcSignal& checksum_sig,
                   std::span<std::uint8_t> payload) noexcept;
/// The same for any kind, the E2E profiles included (their counter byte must be in the payload:
/// 0 is returned, false for Write, when it is not).
std::uint64_t ComputeChecksum(const ChecksumSpec& spec, const bus::DbcSignal& checksum_sig,
                              std::span<const std::uint8_t> payload) noexcept;
bool WriteChecksum(const ChecksumSpec& spec, const bus::DbcSignal& checksum_sig,
                   std::span<std::uint8_t> payload) noexcept;

}  // namespace wheelhil::emulator
