#include "emulator/devices/frame_checksum.h"

#include <array>
#include <cstring>

#include "bus/dbc_codec.h"

namespace wheelhil::emulator {

std::optional<ChecksumKind> ParseChecksumKind(std::string_view name) noexcept {
  if (name == "xor") return ChecksumKind::kXor;
  if (name == "sum") return ChecksumKind::kSum;
  if (name == "crc8_sae_j1850" || name == "crc8") return ChecksumKind::kCrc8SaeJ1850;
  if (name == "crc8_h2f") return ChecksumKind::kCrc8H2F;
  if (name == "crc16_ccitt") return ChecksumKind::kCrc16Ccitt;
  if (name == "e2e_p11") return ChecksumKind::kE2eP11;
  if (name == "e2e_p22") return ChecksumKind::kE2eP22;
  if (name == "crc") return ChecksumKind::kCrcCustom;
  return std::nullopt;
}

std::string_view ChecksumKindNames() noexcept {
  return "xor, sum, crc8_sae_j1850, crc8_h2f, crc16_ccitt, e2e_p11, e2e_p22, crc";
}

std::string WhyChecksumDoesNotFit(const ChecksumSpec& spec, const bus::DbcSignal& sig,
                                  const bus::DbcMessage& msg) {
  const ChecksumKind kind = spec.kind;
  if (kind == ChecksumKind::kCrcCustom && spec.crc.width != sig.length) {
    return std::string(sig.name) + " has " + std::to_string(sig.length) + " bits, the crc " +
           std::to_string(spec.crc.width);
  }
  const bool e2e = kind == ChecksumKind::kE2eP11 || kind == ChecksumKind::kE2eP22;
  if (!ChecksumFits(kind, sig)) {
    return std::string(sig.name) + " (" + std::to_string(sig.length) + " bits" +
           (e2e && sig.start_bit % 8 != 0 ? ", not on a byte boundary" : "") +
           ") cannot carry a " + std::string(ChecksumKindName(kind)) + " checksum";
  }
  if (e2e && sig.start_bit / 8 + 1 >= msg.length) {
    return std::string(sig.name) + " is the last byte of " + msg.name + ": a " +
           std::string(ChecksumKindName(kind)) + " counter follows its CRC byte";
  }
  return {};
}

namespace {
std::uint32_t Reflect(std::uint32_t v, int bits) noexcept {
  std::uint32_t r = 0;
  for (int i = 0; i < bits; ++i) r |= ((v >> i) & 1U) << (bits - 1 - i);
  return r;
}
}  // namespace

std::uint32_t Crc(const CrcParams& p, std::span<const std::uint8_t> bytes) noexcept {
  const std::uint32_t top = 1U << (p.width - 1);
  const std::uint32_t mask = p.width == 32 ? ~0U : ((1U << p.width) - 1);
  std::uint32_t reg = p.init & mask;
  for (std::uint8_t b : bytes) {
    const std::uint32_t in = p.reflect_in ? Reflect(b, 8) : b;
    for (int i = 7; i >= 0; --i) {
      const bool bit = ((in >> i) & 1U) != 0;
      const bool msb = (reg & top) != 0;
      reg = (reg << 1) & mask;
      if (bit != msb) reg ^= p.poly;
    }
  }
  if (p.reflect_out) reg = Reflect(reg, p.width);
  return (reg ^ p.xor_out) & mask;
}

std::string_view ChecksumKindName(ChecksumKind kind) noexcept {
  switch (kind) {
    case ChecksumKind::kXor:
      return "xor";
    case ChecksumKind::kSum:
      return "sum";
    case ChecksumKind::kCrc8SaeJ1850:
      return "crc8_sae_j1850";
    case ChecksumKind::kCrc8H2F:
      return "crc8_h2f";
    case ChecksumKind::kCrc16Ccitt:
      return "crc16_ccitt";
    case ChecksumKind::kE2eP11:
      return "e2e_p11";
    case ChecksumKind::kE2eP22:
      return "e2e_p22";
    case ChecksumKind::kCrcCustom:
      return "crc";
  }
  return "?";
}

bool ChecksumFits(ChecksumKind kind, const bus::DbcSignal& sig) noexcept {
  if (sig.value_type != bus::DbcValueType::kInteger) return false;
  switch (kind) {
    case ChecksumKind::kXor:
      return sig.length == 4 || sig.length == 8;
    case ChecksumKind::kSum:
      return sig.length >= 1 && sig.length <= 8;
    case ChecksumKind::kCrc8SaeJ1850:
    case ChecksumKind::kCrc8H2F:
      return sig.length == 8;
    case ChecksumKind::kCrc16Ccitt:
      return sig.length == 16;
    case ChecksumKind::kE2eP11:
    case ChecksumKind::kE2eP22:
      return sig.length == 8 && sig.little_endian && sig.start_bit % 8 == 0;
    case ChecksumKind::kCrcCustom:
      return sig.length >= 1 && sig.length <= 32;  // its width is checked with its spec
  }
  return false;
}

std::uint8_t Crc8SaeJ1850(std::span<const std::uint8_t> bytes) noexcept {
  std::uint8_t crc = 0xFF;
  for (std::uint8_t b : bytes) {
    crc ^= b;
    for (int i = 0; i < 8; ++i) {
      crc = static_cast<std::uint8_t>((crc & 0x80) ? ((crc << 1) ^ 0x1D) : (crc << 1));
    }
  }
  return static_cast<std::uint8_t>(crc ^ 0xFF);
}

std::uint64_t ComputeChecksum(ChecksumKind kind, const bus::DbcSignal& checksum_sig,
                              std::span<const std::uint8_t> payload) noexcept {
  std::array<std::uint8_t, 64> buf{};
  if (payload.size() > buf.size()) return 0;
  std::memcpy(buf.data(), payload.data(), payload.size());
  const std::span<std::uint8_t> work(buf.data(), payload.size());
  if (!bus::InsertRaw(checksum_sig, 0, work)) return 0;
  const int w = checksum_sig.length;
  const std::uint64_t mask = w >= 64 ? ~0ULL : ((1ULL << w) - 1);
  switch (kind) {
    case ChecksumKind::kXor: {
      std::uint8_t x = 0;
      for (std::uint8_t b : work) x ^= b;
      if (w == 4) x = static_cast<std::uint8_t>((x & 0x0F) ^ (x >> 4));
      return x & mask;
    }
    case ChecksumKind::kSum: {
      std::uint64_t s = 0;
      for (std::uint8_t b : work) s += b;
      return s & mask;
    }
    case ChecksumKind::kCrc8SaeJ1850:
      return Crc8SaeJ1850(work) & mask;
    case ChecksumKind::kCrc8H2F:
      return Crc(kCrc8H2FParams, work) & mask;
    case ChecksumKind::kCrc16Ccitt:
      return Crc(kCrc16CcittFalseParams, work) & mask;
    case ChecksumKind::kE2eP11:
    case ChecksumKind::kE2eP22:
    case ChecksumKind::kCrcCustom:
      return 0;  // need their parameters: the ChecksumSpec form
  }
  return 0;
}

std::uint64_t ComputeChecksum(const ChecksumSpec& spec, const bus::DbcSignal& checksum_sig,
                              std::span<const std::uint8_t> payload) noexcept {
  if (spec.kind == ChecksumKind::kCrcCustom) {
    std::array<std::uint8_t, 64> buf{};
    if (payload.size() > buf.size() || spec.crc.width != checksum_sig.length) return 0;
    std::copy(payload.begin(), payload.end(), buf.begin());
    const std::span<std::uint8_t> work(buf.data(), payload.size());
    if (!bus::InsertRaw(checksum_sig, 0, work)) return 0;
    return Crc(spec.crc, work);
  }
  if (spec.kind != ChecksumKind::kE2eP11 && spec.kind != ChecksumKind::kE2eP22) {
    return ComputeChecksum(spec.kind, checksum_sig, payload);
  }
  const std::size_t k = static_cast<std::size_t>(checksum_sig.start_bit) / 8;
  if (!ChecksumFits(spec.kind, checksum_sig) || k + 1 >= payload.size() || payload.size() > 64) {
    return 0;
  }
  std::array<std::uint8_t, 66> buf{};
  std::size_t n = 0;
  if (spec.kind == ChecksumKind::kE2eP11) {
    buf[n++] = static_cast<std::uint8_t>(spec.data_id & 0xFF);
    buf[n++] = spec.data_id_nibble ? 0 : static_cast<std::uint8_t>(spec.data_id >> 8);
  }
  for (std::size_t i = 0; i < payload.size(); ++i) {
    if (i != k) buf[n++] = payload[i];
  }
  if (spec.kind == ChecksumKind::kE2eP22) {
    buf[n++] = spec.data_id_list[payload[k + 1] & 0x0F];
    return Crc(kCrc8H2FParams, std::span<const std::uint8_t>(buf.data(), n));
  }
  return Crc(CrcParams{8, 0x1D, 0x00, false, false, 0x00},
             std::span<const std::uint8_t>(buf.data(), n));
}

bool WriteChecksum(const ChecksumSpec& spec, const bus::DbcSignal& checksum_sig,
                   std::span<std::uint8_t> payload) noexcept {
  if (spec.kind == ChecksumKind::kCrcCustom) {
    std::uint64_t unused = 0;
    if (spec.crc.width != checksum_sig.length || !bus::ExtractRaw(checksum_sig, payload, unused)) {
      return false;
    }
    return bus::InsertRaw(checksum_sig, ComputeChecksum(spec, checksum_sig, payload), payload);
  }
  if (spec.kind != ChecksumKind::kE2eP11 && spec.kind != ChecksumKind::kE2eP22) {
    return WriteChecksum(spec.kind, checksum_sig, payload);
  }
  const std::size_t k = static_cast<std::size_t>(checksum_sig.start_bit) / 8;
  if (!ChecksumFits(spec.kind, checksum_sig) || k + 1 >= payload.size()) return false;
  return bus::InsertRaw(checksum_sig, ComputeChecksum(spec, checksum_sig, payload), payload);
}

bool WriteChecksum(ChecksumKind kind, const bus::DbcSignal& checksum_sig,
                   std::span<std::uint8_t> payload) noexcept {
  std::uint64_t unused = 0;
  if (!bus::ExtractRaw(checksum_sig, payload, unused)) return false;
  return bus::InsertRaw(checksum_sig, ComputeChecksum(kind, checksum_sig, payload), payload);
}

}  // namespace wheelhil::emulator
