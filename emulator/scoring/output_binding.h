#pragma once
/// Where a firmware's estimates are in its own frames: the scenario's `firmware.outputs` (every
/// key in docs/scenarios.md, a walk-through in docs/own-hardware.md). A binding names a DBC file
/// and, per output stream, the message that carries it and the signal of each value:
///
///     outputs:
///       dbc: my_fw.dbc                  # relative to the file the binding is written in
///       streams:
///         pose:  {kind: pose, message: EST_Pose, x: X, y: Y, theta: Theta}
///         twist: {kind: velocity, message: EST_Vel, vx: Vx, omega: Wz, timestamp: T_ms}
///         slip:  {kind: slip, message: EST_Slip, flags: Flags, counter: Cnt}
///
/// `outputs` may also be the path of a file holding that mapping (wheelhil's own firmware has
/// scenarios/firmware/wheelhil_fw_outputs.yaml); a `dbc` of `${DBC_DIR}/<file>` is a file of
/// wheelhil's DBC directory. A value is a signal name, or {signal, unit, gain} where `unit`
/// replaces the DBC's unit string and `gain` multiplies the SI value. Units come from the DBC
/// (bus/dbc_units.h): m, mm, cm; rad, deg; m/s, mm/s; rad/s, deg/s, rpm; s, ms, us.
///
/// A stream's sample is time-stamped (s since the motion start) by its frame's arrival on the
/// bus; with `cycle: SIG` by the SYNC that opened cycle SIG (counted mod 2^bits of SIG); with
/// `timestamp: SIG` by that signal on the firmware's clock, whose origin is placed at the
/// stream's first frame. Bus checks of the stream's message: cycle time against
/// GenMsgCycleTime (or `cycle_time_ms`), with `cycle_tolerance` (a fraction, 0.1 by default);
/// the DLC against the DBC's; a rolling `counter` (`{signal, step, modulo}`) and a `checksum`
/// (`{signal, type}`: xor, sum, crc8_sae_j1850, crc8_h2f, crc16_ccitt; frame_checksum.h).
///
/// Reading checks the binding's shape (kinds, keys, names) and throws std::invalid_argument
/// "file:line:col: field: problem"; Resolve checks it against the DBC (a missing message or
/// signal, a unit that does not convert, a counter or checksum a signal cannot carry) and
/// throws the same form. Value types; thread-compatible.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "bus/dbc.h"
#include "bus/dbc_units.h"
#include "bus/yaml_fields.h"
#include "emulator/devices/frame_checksum.h"

namespace wheelhil::emulator::scoring {

enum class OutputKind : std::uint8_t { kPose, kVelocity, kSlip };

/// One signal of a binding, with where it is written.
struct SignalBindingSpec {
  std::string signal;  ///< Empty: not bound.
  std::string unit;    ///< Replaces the DBC signal's unit when not empty.
  double gain = 1.0;
  std::string where;  ///< file:line:col.
  std::string field;  ///< Dotted field name ("firmware.outputs.streams.pose.x").
  bool bound() const { return !signal.empty(); }
};

struct OutputStreamSpec {
  std::string name;
  OutputKind kind = OutputKind::kPose;
  std::string message;
  std::string where, field;
  /// The kind's values in the order of OutputRoles(kind); unbound ones are optional.
  std::vector<SignalBindingSpec> values;
  SignalBindingSpec cycle, timestamp;
  std::optional<double> cycle_time_ms;  ///< Replaces GenMsgCycleTime.
  double cycle_tolerance = 0.1;
  SignalBindingSpec counter;
  std::int64_t counter_step = 1;
  std::optional<std::uint64_t> counter_modulo;  ///< Default 2^bits of the counter signal.
  SignalBindingSpec checksum;
  ChecksumSpec checksum_kind;
};

struct OutputsSpec {
  std::string dbc;  ///< Absolute, or "${DBC_DIR}/<file>".
  std::string dbc_where, dbc_field;
  std::vector<OutputStreamSpec> streams;
};

/// The values a kind binds, in order: pose x, y, theta; velocity vx, vy, omega; slip flags,
/// detected, calibrated, residual, band_lower, band_upper.
const std::vector<std::string_view>& OutputRoles(OutputKind kind);
/// What each role measures (the units that fit it).
bus::PhysicalQuantity RoleQuantity(OutputKind kind, std::size_t role);

/// Reads `firmware.outputs` (`n`: a mapping, or a string naming a binding file relative to
/// `base_dir`). `field` is the node's dotted name.
OutputsSpec ReadOutputs(const bus::yaml::FieldReader& r, const YAML::Node& n,
                        const std::string& field, const std::string& base_dir);

/// One bound signal resolved against the DBC.
struct ResolvedSignal {
  const bus::DbcSignal* signal = nullptr;  ///< nullptr: not bound.
  bus::UnitToSi to_si;                      ///< Includes the gain.
};

struct ResolvedStream {
  const OutputStreamSpec* spec = nullptr;
  const bus::DbcMessage* message = nullptr;
  std::vector<ResolvedSignal> values;  ///< As OutputStreamSpec::values.
  ResolvedSignal cycle, timestamp, counter, checksum;
  std::uint64_t cycle_modulo = 256;    ///< 2^bits of the cycle signal (capped at 2^32).
  std::uint64_t counter_modulo = 256;
  std::optional<double> expected_cycle_s;  ///< cycle_time_ms or GenMsgCycleTime.
};

/// A binding checked against its DBC. Owns the spec and the database its pointers point into;
/// movable, not copyable.
class OutputBinding {
 public:
  OutputBinding() = default;
  /// Loads the DBC (`${DBC_DIR}` replaced by `dbc_dir`) and resolves every stream.
  static OutputBinding Resolve(OutputsSpec spec, const std::string& dbc_dir);

  bool empty() const { return streams_.empty(); }
  const std::vector<ResolvedStream>& streams() const { return streams_; }
  const bus::DbcDatabase* dbc() const { return dbc_.get(); }

 private:
  std::unique_ptr<OutputsSpec> spec_;
  std::unique_ptr<const bus::DbcDatabase> dbc_;
  std::vector<ResolvedStream> streams_;
};

}  // namespace wheelhil::emulator::scoring
