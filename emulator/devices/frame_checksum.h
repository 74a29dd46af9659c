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
/// Stateless, noexcept, no allocation; thread-safe.

#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

#include "bus/dbc.h"

namespace wheelhil::emulator {

enum class ChecksumKind : std::uint8_t { kXor, kSum, kCrc8SaeJ1850, kCrc8H2F, kCrc16Ccitt };

/// "xor", "sum", "crc8_sae_j1850" (also "crc8"), "crc8_h2f", "crc16_ccitt"; nullopt for
/// anything else.
std::optional<ChecksumKind> ParseChecksumKind(std::string_view name) noexcept;
std::string_view ChecksumKindName(ChecksumKind kind) noexcept;
/// The accepted names, for messages: "xor, sum, crc8_sae_j1850, crc8_h2f, crc16_ccitt".
std::string_view ChecksumKindNames() noexcept;

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
inline constexpr CrcParams kCrc8SaeJ1850Params{8, 0x1D, 0xFF, false, false, 0xFF};
inline constexpr CrcParams kCrc8H2FParams{8, 0x2F, 0xFF, false, false, 0xFF};
inline constexpr CrcParams kCrc16CcittFalseParams{16, 0x1021, 0xFFFF, false, false, 0x0000};
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

}  // namespace wheelhil::emulator
