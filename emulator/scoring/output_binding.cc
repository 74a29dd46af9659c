#include "emulator/scoring/output_binding.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <set>
#include <stdexcept>

#include <fmt/format.h>

#include "emulator/devices/checksum_yaml.h"

namespace wheelhil::emulator::scoring {

namespace {

namespace fs = std::filesystem;
using bus::PhysicalQuantity;
using bus::yaml::FieldReader;

constexpr std::string_view kDbcDir = "${DBC_DIR}/";

// Blocks of report.json's metrics that a stream must not replace.
const std::set<std::string>& ReservedNames() {
  static const std::set<std::string> names{"truth", "bus",      "faults", "contact",
                                           "correction", "residual"};
  return names;
}

bool IsIdentifier(const std::string& s) {
  if (s.empty() || !(std::isalpha(static_cast<unsigned char>(s[0])) != 0)) return false;
  return std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_';
  });
}

std::optional<OutputKind> ParseKind(const std::string& s) {
  if (s == "pose") return OutputKind::kPose;
  if (s == "velocity") return OutputKind::kVelocity;
  if (s == "slip") return OutputKind::kSlip;
  return std::nullopt;
}

// `key: SIG` or `key: {signal: SIG, unit: U, gain: G}`.
SignalBindingSpec ReadSignal(const FieldReader& r, const YAML::Node& parent,
                             const std::string& key, const std::string& prefix,
                             std::set<std::string> extra_keys = {}) {
  SignalBindingSpec s;
  const YAML::Node n = FieldReader::Get(parent, key);
  if (!FieldReader::Present(n)) return s;
  s.field = FieldReader::Join(prefix, key);
  s.where = r.Where(n);
  if (n.IsScalar()) {
    s.signal = r.ToString(n, s.field);
  } else {
    extra_keys.insert({"signal", "unit", "gain"});
    r.CheckKeys(n, s.field, extra_keys);
    s.signal = r.String(n, "signal", s.field, std::nullopt);
    s.unit = r.String(n, "unit", s.field, std::string());
    s.gain = r.Number(n, "gain", s.field, -1e9, 1e9, 1.0);
    if (s.gain == 0) r.FailKey(n, "gain", s.field + ".gain", "must not be 0");
  }
  if (s.signal.empty()) r.Fail(n, s.field, "names no signal");
  return s;
}

OutputStreamSpec ReadStream(const FieldReader& r, const YAML::Node& key, const YAML::Node& n,
                            const std::string& prefix) {
  OutputStreamSpec s;
  s.name = r.ToString(key, prefix);
  s.field = FieldReader::Join(prefix, s.name);
  s.where = r.Where(n);
  if (!IsIdentifier(s.name)) {
    r.Fail(key, s.field, "a stream's name is a letter, then letters, digits or '_'");
  }
  if (ReservedNames().contains(s.name)) {
    r.Fail(key, s.field,
           fmt::format("'{}' is a block of the report's metrics; name the stream otherwise",
                       s.name));
  }
  if (!n.IsMap()) r.Fail(n, s.field, "must be a mapping {kind, message, ...}");
  const std::string kind = r.String(n, "kind", s.field, std::nullopt);
  const auto k = ParseKind(kind);
  if (!k) r.FailKey(n, "kind", s.field + ".kind", fmt::format("'{}' is not pose, velocity or slip", kind));
  s.kind = *k;
  std::set<std::string> allowed{"kind",           "message",         "cycle",   "timestamp",
                                "cycle_time_ms",  "cycle_tolerance", "counter", "checksum"};
  for (std::string_view role : OutputRoles(s.kind)) allowed.emplace(role);
  r.CheckKeys(n, s.field, allowed);
  s.message = r.String(n, "message", s.field, std::nullopt);
  for (std::string_view role : OutputRoles(s.kind)) {
    s.values.push_back(ReadSignal(r, n, std::string(role), s.field));
  }
  auto require = [&](std::size_t role) {
    if (!s.values[role].bound()) {
      r.Fail(n, FieldReader::Join(s.field, OutputRoles(s.kind)[role]), "is required");
    }
  };
  switch (s.kind) {
    case OutputKind::kPose:
      require(0), require(1);
      break;
    case OutputKind::kVelocity:
      require(0), require(2);
      break;
    case OutputKind::kSlip:
      if (s.values[0].bound() == s.values[1].bound()) {
        r.Fail(n, s.field, "needs exactly one of flags (bit i: wheel i slips) and detected");
      }
      if (s.values[4].bound() != s.values[5].bound()) {
        r.Fail(n, s.field, "band_lower and band_upper go together");
      }
      break;
  }
  s.cycle = ReadSignal(r, n, "cycle", s.field);
  s.timestamp = ReadSignal(r, n, "timestamp", s.field);
  if (s.cycle.bound() && s.timestamp.bound()) {
    r.Fail(n, s.field, "cycle and timestamp both give the sample's time: choose one");
  }
  if (FieldReader::Present(FieldReader::Get(n, "cycle_time_ms"))) {
    s.cycle_time_ms = r.Number(n, "cycle_time_ms", s.field, 0.001, 3.6e6);
  }
  s.cycle_tolerance = r.Number(n, "cycle_tolerance", s.field, 0, 10, 0.1);
  const YAML::Node counter = FieldReader::Get(n, "counter");
  s.counter = ReadSignal(r, n, "counter", s.field, {"step", "modulo"});
  if (counter.IsMap()) {
    s.counter_step = r.Integer(counter, "step", s.counter.field, -65535, 65535, 1);
    if (FieldReader::Present(FieldReader::Get(counter, "modulo"))) {
      s.counter_modulo = static_cast<std::uint64_t>(
          r.Integer(counter, "modulo", s.counter.field, 2, 1LL << 32));
    }
  }
  const YAML::Node checksum = FieldReader::Get(n, "checksum");
  s.checksum = ReadSignal(r, n, "checksum", s.field, ChecksumSpecKeys());
  if (s.checksum.bound()) {
    if (!checksum.IsMap()) {
      r.Fail(checksum, s.checksum.field, "must be {signal, type}");
    }
    s.checksum_kind = ReadChecksumSpec(r, checksum, s.checksum.field);
  }
  return s;
}

OutputsSpec ReadMapping(const FieldReader& r, const YAML::Node& n, const std::string& field,
                        const fs::path& base_dir) {
  r.CheckKeys(n, field, {"dbc", "streams"});
  OutputsSpec o;
  o.dbc = r.String(n, "dbc", field, std::nullopt);
  o.dbc_field = FieldReader::Join(field, "dbc");
  o.dbc_where = r.Where(n["dbc"]);
  if (!o.dbc.starts_with(kDbcDir)) {
    if (!fs::path(o.dbc).is_absolute()) o.dbc = (base_dir / o.dbc).lexically_normal().string();
    if (!fs::is_regular_file(o.dbc)) r.Fail(n["dbc"], o.dbc_field, o.dbc + " not found");
  }
  const std::string sf = FieldReader::Join(field, "streams");
  const YAML::Node streams = FieldReader::Get(n, "streams");
  if (!streams.IsMap() || streams.size() == 0) {
    r.FailKey(n, "streams", sf, "must map stream names to {kind, message, ...}");
  }
  for (auto it = streams.begin(); it != streams.end(); ++it) {
    // A repeated stream name is a duplicate key, refused when the file is parsed.
    o.streams.push_back(ReadStream(r, it->first, it->second, sf));
  }
  return o;
}

// The codec's raw range of an integer signal, capped at 2^32 values.
std::uint64_t Modulo(const bus::DbcSignal& s) {
  return s.length >= 32 ? (1ULL << 32) : (1ULL << s.length);
}

[[noreturn]] void Fail(const std::string& where, const std::string& field,
                       const std::string& problem) {
  throw std::invalid_argument(fmt::format("{}: {}: {}", where, field, problem));
}

// `q` empty: a raw value (counter, checksum, cycle), whatever its unit string says.
ResolvedSignal ResolveSignal(const SignalBindingSpec& b, const bus::DbcMessage& msg,
                             std::optional<PhysicalQuantity> q, const std::string& dbc_name) {
  ResolvedSignal out;
  if (!b.bound()) return out;
  out.signal = msg.FindSignal(b.signal);
  if (out.signal == nullptr) {
    std::vector<std::string> names;
    for (const auto& s : msg.signals) names.push_back(s.name);
    Fail(b.where, b.field,
         fmt::format("message {} of {} has no signal '{}' (it has: {})", msg.name, dbc_name,
                     b.signal, fmt::join(names, ", ")));
  }
  if (!q) return out;
  const std::string& unit = b.unit.empty() ? out.signal->unit : b.unit;
  const auto to_si = bus::ConvertUnit(unit, *q);
  if (!to_si) {
    Fail(b.where, b.field,
         fmt::format("{}'s unit '{}'{} is not a unit of {} ({}){}", b.signal, unit,
                     b.unit.empty() ? fmt::format(" (in {})", dbc_name) : std::string(),
                     bus::PhysicalQuantityName(*q), bus::AcceptedUnits(*q),
                     b.unit.empty() ? "; give the binding's own: {signal, unit}" : ""));
  }
  out.to_si = bus::UnitToSi{to_si->scale * b.gain, to_si->offset * b.gain};
  return out;
}

void RequireInteger(const SignalBindingSpec& b, const ResolvedSignal& s, const char* what) {
  if (!s.signal->IsRawInteger()) {
    Fail(b.where, b.field,
         fmt::format("{} {} must be an integer signal with factor 1 and offset 0", what,
                     b.signal));
  }
}

}  // namespace

const std::vector<std::string_view>& OutputRoles(OutputKind kind) {
  static const std::vector<std::string_view> pose{"x", "y", "theta"};
  static const std::vector<std::string_view> velocity{"vx", "vy", "omega"};
  static const std::vector<std::string_view> slip{"flags",    "detected",   "calibrated",
                                                  "residual", "band_lower", "band_upper"};
  switch (kind) {
    case OutputKind::kPose: return pose;
    case OutputKind::kVelocity: return velocity;
    case OutputKind::kSlip: return slip;
  }
  return pose;
}

PhysicalQuantity RoleQuantity(OutputKind kind, std::size_t role) {
  switch (kind) {
    case OutputKind::kPose:
      return role < 2 ? PhysicalQuantity::kLength : PhysicalQuantity::kAngle;
    case OutputKind::kVelocity:
      return role < 2 ? PhysicalQuantity::kSpeed : PhysicalQuantity::kAngularRate;
    case OutputKind::kSlip:
      return role < 3 ? PhysicalQuantity::kDimensionless : PhysicalQuantity::kAngle;
  }
  return PhysicalQuantity::kDimensionless;
}

OutputsSpec ReadOutputs(const FieldReader& r, const YAML::Node& n, const std::string& field,
                        const std::string& base_dir) {
  if (n.IsScalar()) {
    fs::path file = r.ToString(n, field);
    if (!file.is_absolute()) file = (fs::path(base_dir) / file).lexically_normal();
    if (!fs::is_regular_file(file)) r.Fail(n, field, file.string() + " not found");
    const FieldReader file_reader(file.string());
    return file_reader.Guard([&] {
      const YAML::Node doc = file_reader.Parse(file_reader.ReadFile());
      return ReadMapping(file_reader, doc, "outputs", file.parent_path());
    });
  }
  if (!n.IsMap()) r.Fail(n, field, "must be a mapping {dbc, streams} or a binding file's path");
  return ReadMapping(r, n, field, base_dir);
}

OutputBinding OutputBinding::Resolve(OutputsSpec spec, const std::string& dbc_dir) {
  OutputBinding b;
  b.spec_ = std::make_unique<OutputsSpec>(std::move(spec));
  std::string path = b.spec_->dbc;
  if (path.starts_with(kDbcDir)) path = dbc_dir + "/" + path.substr(kDbcDir.size());
  try {
    b.dbc_ = std::make_unique<const bus::DbcDatabase>(bus::DbcDatabase::LoadFile(path));
  } catch (const std::exception& e) {
    Fail(b.spec_->dbc_where, b.spec_->dbc_field, e.what());
  }
  const std::string dbc_name = fs::path(path).filename().string();
  for (const OutputStreamSpec& s : b.spec_->streams) {
    ResolvedStream rs;
    rs.spec = &s;
    rs.message = b.dbc_->FindMessage(s.message);
    if (rs.message == nullptr) {
      Fail(s.where, s.field + ".message", fmt::format("{} has no message '{}'", dbc_name, s.message));
    }
    for (std::size_t i = 0; i < s.values.size(); ++i) {
      rs.values.push_back(ResolveSignal(s.values[i], *rs.message, RoleQuantity(s.kind, i), dbc_name));
    }
    rs.cycle = ResolveSignal(s.cycle, *rs.message, std::nullopt, dbc_name);
    if (rs.cycle.signal != nullptr) {
      RequireInteger(s.cycle, rs.cycle, "the cycle");
      rs.cycle_modulo = Modulo(*rs.cycle.signal);
    }
    rs.timestamp = ResolveSignal(s.timestamp, *rs.message, PhysicalQuantity::kTime, dbc_name);
    rs.counter = ResolveSignal(s.counter, *rs.message, std::nullopt, dbc_name);
    if (rs.counter.signal != nullptr) {
      RequireInteger(s.counter, rs.counter, "the counter");
      rs.counter_modulo = s.counter_modulo.value_or(Modulo(*rs.counter.signal));
      if (rs.counter_modulo > Modulo(*rs.counter.signal)) {
        Fail(s.counter.where, s.counter.field,
             fmt::format("modulo {} does not fit the {} bits of {}", rs.counter_modulo,
                         rs.counter.signal->length, s.counter.signal));
      }
    }
    rs.checksum = ResolveSignal(s.checksum, *rs.message, std::nullopt, dbc_name);
    if (rs.checksum.signal != nullptr) {
      if (const std::string why =
              WhyChecksumDoesNotFit(s.checksum_kind, *rs.checksum.signal, *rs.message);
          !why.empty()) {
        Fail(s.checksum.where, s.checksum.field, why);
      }
    }
    if (s.cycle_time_ms) {
      rs.expected_cycle_s = *s.cycle_time_ms * 1e-3;
    } else if (rs.message->cycle_time_ms && *rs.message->cycle_time_ms > 0) {
      rs.expected_cycle_s = *rs.message->cycle_time_ms * 1e-3;
    }
    b.streams_.push_back(std::move(rs));
  }
  return b;
}

}  // namespace wheelhil::emulator::scoring
