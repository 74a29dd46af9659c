#pragma once
/// Packs and unpacks DBC signals (bus/dbc.h) to and from frame payloads. The per-signal calls
/// are the hot path of every virtual device and of the firmware: noexcept, no allocation, no
/// exceptions; bad input is reported through the return value. Payload bytes a signal does not
/// cover are never touched. Stateless, so thread-safe for distinct payloads.
///
/// Bit order: Intel (@1) numbers bits LSB-first from bit 0 of byte 0; Motorola (@0) gives the
/// MSB in DBC "sawtooth" numbering (byte b, bit i -> 8*b + i) and the signal continues towards
/// bit 0 of the same byte, then bit 7 of the next byte.

#include <cstdint>
#include <functional>
#include <map>
#include <span>
#include <string>

#include "bus/can_frame.h"
#include "bus/dbc.h"

namespace wheelhil::bus {

/// Raw bits of `sig` in `payload`, unsigned (no sign extension). False when the payload is too
/// short for the signal.
bool ExtractRaw(const DbcSignal& sig, std::span<const std::uint8_t> payload,
                std::uint64_t& raw) noexcept;
/// Raw value with sign extension for signed signals (the bit pattern for floats).
bool ExtractRawSigned(const DbcSignal& sig, std::span<const std::uint8_t> payload,
                      std::int64_t& raw) noexcept;
/// Writes the low `length` bits of `raw` into `payload`. False when the payload is too short
/// (nothing written).
bool InsertRaw(const DbcSignal& sig, std::uint64_t raw, std::span<std::uint8_t> payload) noexcept;

/// Physical value (raw * factor + offset; IEEE value * factor + offset for float signals).
/// Returns NaN when the payload is too short for the signal.
double DecodeSignal(const DbcSignal& sig, std::span<const std::uint8_t> payload) noexcept;

/// Physical -> raw: raw = round_half_away((physical - offset) / factor), saturated to the raw
/// range of the signal ([0, 2^n-1] unsigned, [-2^(n-1), 2^(n-1)-1] signed); NaN encodes as raw
/// 0. The DBC [min|max] range is not enforced (it is documentation; clamp before if needed).
/// Float signals (SIG_VALTYPE_) store (physical - offset) / factor as IEEE single/double; a
/// finite value beyond the float range becomes +-inf and counts as saturated.
/// Returns true when the value was encoded (rounded to the raw resolution); false when it was
/// saturated, was NaN, or the payload is too short (then nothing is written).
bool EncodeSignal(const DbcSignal& sig, double physical, std::span<std::uint8_t> payload) noexcept;

/// The smallest and largest physical value the signal can carry (after factor/offset).
double SignalPhysicalMin(const DbcSignal& sig) noexcept;
double SignalPhysicalMax(const DbcSignal& sig) noexcept;

/// Signal values by name, physical units.
using SignalValues = std::map<std::string, double, std::less<>>;

/// Builds a frame for `msg` (id, extended, length = msg.length, all other bytes zero).
/// Signals missing from `values` are encoded as raw 0 (all their bits zero), which for a signal
/// with an offset is the physical value `offset`. In a multiplexed message only the signals of
/// the multiplexer value given in `values` are written (a missing multiplexer means value 0).
/// Returns false, with `problem` saying which, when a name in `values` is not a signal of the
/// message or belongs to another multiplexer value, or a value had to be saturated; `out` is
/// still filled with everything that could be encoded.
bool EncodeMessage(const DbcMessage& msg, const SignalValues& values, CanFrame& out,
                   std::string* problem = nullptr);
/// Convenience form: returns the frame, ignoring problems.
CanFrame EncodeMessage(const DbcMessage& msg, const SignalValues& values);

/// Decodes every signal present in the frame: all non-multiplexed signals and, for a
/// multiplexed message, the `m<n>` signals whose n equals the multiplexer's raw value. Signals
/// the payload is too short for are left out (a short frame never reads past its length).
SignalValues DecodeMessage(const DbcMessage& msg, const CanFrame& frame);

/// One signal of `msg` exactly as DecodeMessage decodes it, without building the map: true and
/// `*out` = its physical value when DecodeMessage would list it (multiplexer value matches, the
/// payload is long enough); false, `*out` untouched, when DecodeMessage would leave it out.
bool DecodeSignalIfPresent(const DbcMessage& msg, const DbcSignal& sig, const CanFrame& frame,
                           double* out) noexcept;

}  // namespace wheelhil::bus
