#include "bus/dbc_codec.h"

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

namespace wheelhil::bus {
namespace {

constexpr std::uint64_t Mask(int length) noexcept {
  return length >= 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << length) - 1;
}

// Motorola MSB in linear numbering: byte 0 bit 7 = 0, byte 0 bit 0 = 7, byte 1 bit 7 = 8.
constexpr int MotorolaLinear(int sawtooth_bit) noexcept {
  return (sawtooth_bit / 8) * 8 + 7 - sawtooth_bit % 8;
}

std::uint64_t LoadLe(std::span<const std::uint8_t> p) noexcept {
  if constexpr (std::endian::native == std::endian::little) {
    // A whole 8-byte window (every classic frame's data array): one load, no staging copy.
    std::uint64_t v = 0;
    if (p.size() >= 8) {
      std::memcpy(&v, p.data(), 8);
    } else {
      std::memcpy(&v, p.data(), p.size());
    }
    return v;
  } else {
    std::uint8_t buf[8] = {};
    std::memcpy(buf, p.data(), std::min<std::size_t>(p.size(), 8));
    std::uint64_t v = 0;
    for (int i = 7; i >= 0; --i) v = v << 8 | buf[i];
    return v;
  }
}

void StoreLe(std::uint64_t v, std::span<std::uint8_t> p) noexcept {
  if constexpr (std::endian::native == std::endian::little) {
    if (p.size() >= 8) {
      std::memcpy(p.data(), &v, 8);
      return;
    }
  }
  const std::size_t n = std::min<std::size_t>(p.size(), 8);
  for (std::size_t i = 0; i < n; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

std::uint64_t LoadBe(std::span<const std::uint8_t> p) noexcept {
  const std::uint64_t le = LoadLe(p);
  return __builtin_bswap64(le);
}

void StoreBe(std::uint64_t v, std::span<std::uint8_t> p) noexcept {
  StoreLe(__builtin_bswap64(v), p);
}

// Range of linear bits the signal occupies, or false for a malformed hand-built signal.
// Intel linear bit p = byte p/8, bit p%8 (LSB first). Motorola linear bit q = byte q/8,
// bit 7 - q%8 (MSB first).
bool BitRange(const DbcSignal& sig, int& lsb, int& last) noexcept {
  if (sig.length < 1 || sig.length > 64 || sig.start_bit < 0 || sig.start_bit >= 512) {
    return false;
  }
  if (sig.little_endian) {
    lsb = sig.start_bit;
    last = sig.start_bit + sig.length - 1;
  } else {
    lsb = MotorolaLinear(sig.start_bit) + sig.length - 1;
    last = lsb;
  }
  return true;
}

}  // namespace

bool ExtractRaw(const DbcSignal& sig, std::span<const std::uint8_t> payload,
                std::uint64_t& raw) noexcept {
  int lsb = 0, last = 0;
  if (!BitRange(sig, lsb, last)) return false;
  if (static_cast<std::size_t>(last / 8) >= payload.size()) return false;
  if (last < 64) {
    raw = sig.little_endian ? (LoadLe(payload) >> sig.start_bit) & Mask(sig.length)
                            : (LoadBe(payload) >> (63 - lsb)) & Mask(sig.length);
    return true;
  }
  std::uint64_t v = 0;  // CAN FD payloads beyond byte 8: bit by bit
  for (int k = 0; k < sig.length; ++k) {
    const int p = sig.little_endian ? sig.start_bit + k : lsb - k;
    const int shift = sig.little_endian ? (p & 7) : 7 - (p & 7);
    v |= static_cast<std::uint64_t>((payload[static_cast<std::size_t>(p >> 3)] >> shift) & 1u) << k;
  }
  raw = v;
  return true;
}

bool ExtractRawSigned(const DbcSignal& sig, std::span<const std::uint8_t> payload,
                      std::int64_t& raw) noexcept {
  std::uint64_t u = 0;
  if (!ExtractRaw(sig, payload, u)) return false;
  if (sig.is_signed && sig.value_type == DbcValueType::kInteger && sig.length < 64 &&
      (u >> (sig.length - 1)) & 1u) {
    u |= ~Mask(sig.length);
  }
  raw = static_cast<std::int64_t>(u);
  return true;
}

bool InsertRaw(const DbcSignal& sig, std::uint64_t raw, std::span<std::uint8_t> payload) noexcept {
  int lsb = 0, last = 0;
  if (!BitRange(sig, lsb, last)) return false;
  if (static_cast<std::size_t>(last / 8) >= payload.size()) return false;
  raw &= Mask(sig.length);
  if (last < 64) {
    if (sig.little_endian) {
      const std::uint64_t m = Mask(sig.length) << sig.start_bit;
      StoreLe((LoadLe(payload) & ~m) | (raw << sig.start_bit), payload);
    } else {
      const int shift = 63 - lsb;
      const std::uint64_t m = Mask(sig.length) << shift;
      StoreBe((LoadBe(payload) & ~m) | (raw << shift), payload);
    }
    return true;
  }
  for (int k = 0; k < sig.length; ++k) {
    const int p = sig.little_endian ? sig.start_bit + k : lsb - k;
    const int shift = sig.little_endian ? (p & 7) : 7 - (p & 7);
    std::uint8_t& byte = payload[static_cast<std::size_t>(p >> 3)];
    byte = static_cast<std::uint8_t>((byte & ~(1u << shift)) | (((raw >> k) & 1u) << shift));
  }
  return true;
}

namespace {

// The physical value of the raw bits ExtractRaw gave (sign-extended as ExtractRawSigned does).
double PhysicalOfRaw(const DbcSignal& sig, std::uint64_t u) noexcept {
  if (sig.is_signed && sig.value_type == DbcValueType::kInteger && sig.length < 64 &&
      (u >> (sig.length - 1)) & 1u) {
    u |= ~Mask(sig.length);
  }
  const auto raw = static_cast<std::int64_t>(u);
  double value = 0.0;
  switch (sig.value_type) {
    case DbcValueType::kFloat32:
      value = std::bit_cast<float>(static_cast<std::uint32_t>(raw));
      break;
    case DbcValueType::kFloat64:
      value = std::bit_cast<double>(static_cast<std::uint64_t>(raw));
      break;
    case DbcValueType::kInteger:
      value = sig.is_signed ? static_cast<double>(raw)
                            : static_cast<double>(static_cast<std::uint64_t>(raw));
      break;
  }
  return value * sig.factor + sig.offset;
}

}  // namespace

double DecodeSignal(const DbcSignal& sig, std::span<const std::uint8_t> payload) noexcept {
  std::uint64_t raw = 0;
  if (!ExtractRaw(sig, payload, raw)) return std::numeric_limits<double>::quiet_NaN();
  return PhysicalOfRaw(sig, raw);
}

bool EncodeSignal(const DbcSignal& sig, double physical, std::span<std::uint8_t> payload) noexcept {
  const double scaled = (physical - sig.offset) / sig.factor;
  if (sig.value_type == DbcValueType::kFloat32) {
    const float value = static_cast<float>(scaled);
    const bool exact = !std::isnan(scaled) && (std::isfinite(value) || !std::isfinite(scaled));
    return InsertRaw(sig, std::bit_cast<std::uint32_t>(value), payload) && exact;
  }
  if (sig.value_type == DbcValueType::kFloat64) {
    return InsertRaw(sig, std::bit_cast<std::uint64_t>(scaled), payload) && !std::isnan(scaled);
  }
  if (std::isnan(scaled)) {
    (void)InsertRaw(sig, 0, payload);
    return false;
  }
  const double r = std::round(scaled);
  std::uint64_t raw = 0;
  bool exact = true;
  if (sig.is_signed) {
    const double limit = static_cast<double>(std::uint64_t{1} << (sig.length - 1));  // 2^(n-1)
    if (r < -limit) {
      raw = std::uint64_t{1} << (sig.length - 1);  // 100..0: the most negative raw value
      exact = false;
    } else if (r >= limit) {
      raw = Mask(sig.length - 1);
      exact = false;
    } else {
      raw = static_cast<std::uint64_t>(static_cast<std::int64_t>(r));
    }
  } else {
    const double limit = sig.length == 64 ? 18446744073709551616.0  // 2^n
                                          : static_cast<double>(std::uint64_t{1} << sig.length);
    if (r < 0) {
      raw = 0;
      exact = false;
    } else if (r >= limit) {
      raw = Mask(sig.length);
      exact = false;
    } else {
      raw = static_cast<std::uint64_t>(r);
    }
  }
  return InsertRaw(sig, raw, payload) && exact;
}

double SignalPhysicalMin(const DbcSignal& sig) noexcept {
  if (sig.value_type == DbcValueType::kFloat32) return std::numeric_limits<float>::lowest();
  if (sig.value_type == DbcValueType::kFloat64) return std::numeric_limits<double>::lowest();
  const double lo = sig.is_signed ? -std::ldexp(1.0, sig.length - 1) : 0.0;
  const double hi =
      sig.is_signed ? std::ldexp(1.0, sig.length - 1) - 1.0 : std::ldexp(1.0, sig.length) - 1.0;
  return std::min(lo * sig.factor, hi * sig.factor) + sig.offset;
}

double SignalPhysicalMax(const DbcSignal& sig) noexcept {
  if (sig.value_type == DbcValueType::kFloat32) return std::numeric_limits<float>::max();
  if (sig.value_type == DbcValueType::kFloat64) return std::numeric_limits<double>::max();
  const double lo = sig.is_signed ? -std::ldexp(1.0, sig.length - 1) : 0.0;
  const double hi =
      sig.is_signed ? std::ldexp(1.0, sig.length - 1) - 1.0 : std::ldexp(1.0, sig.length) - 1.0;
  return std::max(lo * sig.factor, hi * sig.factor) + sig.offset;
}

bool EncodeMessage(const DbcMessage& msg, const SignalValues& values, CanFrame& out,
                   std::string* problem) {
  out = CanFrame{};
  out.id = msg.id;
  out.extended = msg.extended;
  out.len = static_cast<std::uint8_t>(std::clamp(msg.length, 0, 64));
  out.fd = msg.length > 8;
  bool ok = true;
  auto report = [&](std::string text) {
    if (ok && problem) *problem = std::move(text);
    ok = false;
  };
  const std::span<std::uint8_t> payload(out.data.data(), out.len);

  std::int64_t mux_raw = 0;
  if (const DbcSignal* mux = msg.multiplexer()) {
    const auto it = values.find(mux->name);
    if (it != values.end() && !EncodeSignal(*mux, it->second, payload)) {
      report(fmt::format("{}.{}: value {} saturated", msg.name, mux->name, it->second));
    }
    (void)ExtractRawSigned(*mux, payload, mux_raw);
  }
  for (const auto& [name, value] : values) {
    const DbcSignal* sig = msg.FindSignal(name);
    if (!sig) {
      report(fmt::format("{}: no signal named '{}'", msg.name, name));
      continue;
    }
    if (sig->is_multiplexer) continue;
    if (sig->multiplex_value && *sig->multiplex_value != mux_raw) {
      report(fmt::format("{}.{}: belongs to multiplexer value {}, frame has {}", msg.name, name,
                         *sig->multiplex_value, mux_raw));
      continue;
    }
    if (!EncodeSignal(*sig, value, payload)) {
      report(fmt::format("{}.{}: value {} saturated to the {}-bit raw range", msg.name, name, value,
                         sig->length));
    }
  }
  return ok;
}

CanFrame EncodeMessage(const DbcMessage& msg, const SignalValues& values) {
  CanFrame f;
  (void)EncodeMessage(msg, values, f, nullptr);
  return f;
}

SignalValues DecodeMessage(const DbcMessage& msg, const CanFrame& frame) {
  SignalValues out;
  const auto payload = frame.payload();
  std::int64_t mux_raw = 0;
  bool have_mux = false;
  if (const DbcSignal* mux = msg.multiplexer()) {
    have_mux = ExtractRawSigned(*mux, payload, mux_raw);
  }
  for (const auto& sig : msg.signals) {
    if (sig.multiplex_value && (!have_mux || *sig.multiplex_value != mux_raw)) continue;
    std::uint64_t raw = 0;
    if (ExtractRaw(sig, payload, raw)) out.emplace(sig.name, DecodeSignal(sig, payload));
  }
  return out;
}

bool DecodeSignalIfPresent(const DbcMessage& msg, const DbcSignal& sig, const CanFrame& frame,
                           double* out) noexcept {
  const auto payload = frame.payload();
  if (sig.multiplex_value) {
    const DbcSignal* mux = msg.multiplexer();
    std::int64_t mux_raw = 0;
    if (mux == nullptr || !ExtractRawSigned(*mux, payload, mux_raw) ||
        *sig.multiplex_value != mux_raw) {
      return false;
    }
  }
  std::uint64_t raw = 0;
  if (!ExtractRaw(sig, payload, raw)) return false;
  *out = PhysicalOfRaw(sig, raw);  // the bits once: what DecodeSignal would give
  return true;
}

}  // namespace wheelhil::bus
