#include "bus/yaml_fields.h"

#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <map>
#include <stdexcept>

#include "bus/internal/input_file.h"
#include "bus/internal/utf8.h"

namespace wheelhil::bus::yaml {

FieldReader::FieldReader(std::string file) : file_(std::move(file)) {}

std::string FieldReader::Join(std::string_view prefix, std::string_view key) {
  if (prefix.empty()) return std::string(key);
  return fmt::format("{}.{}", prefix, key);
}

std::string FieldReader::Where(const YAML::Node& node) const {
  return Where(node.IsDefined() ? node.Mark() : YAML::Mark::null_mark());
}

std::string FieldReader::Where(const YAML::Mark& mark) const {
  if (mark.is_null()) return fmt::format("{}:0:0", file_);
  return fmt::format("{}:{}:{}", file_, mark.line + 1, mark.column + 1);
}

void FieldReader::Fail(const YAML::Node& at, std::string_view field,
                       std::string_view problem) const {
  Fail(at.IsDefined() ? at.Mark() : YAML::Mark::null_mark(), field, problem);
}

void FieldReader::Fail(const YAML::Mark& at, std::string_view field,
                       std::string_view problem) const {
  throw std::invalid_argument(fmt::format("{}: {}: {}", Where(at), field, problem));
}

void FieldReader::FailKey(const YAML::Node& parent, const std::string& key,
                          std::string_view field, std::string_view problem) const {
  const YAML::Node n = Get(parent, key);
  Fail(n.IsDefined() ? n : parent, field, problem);
}

void FieldReader::FailYaml(const YAML::Exception& e) const {
  if (!e.mark.is_null())
    Fail(e.mark, section_field_.empty() ? "(document)" : section_field_, e.msg);
  Fail(section_mark_, section_field_.empty() ? "(document)" : section_field_, e.msg);
}

std::string FieldReader::ReadFile() const {
  internal::RegularFile f = internal::ReadRegularFile(file_, kMaxFileBytes);
  std::string problem;
  switch (f.problem) {
    case internal::RegularFile::kRead:
      return std::move(f.text);
    case internal::RegularFile::kCannotOpen:
      // (Permission is the one reason a file that is there cannot be opened for reading.)
      problem = f.error == EACCES || f.error == EPERM ? "cannot be read"
                                                      : "cannot be read (no such file)";
      break;
    case internal::RegularFile::kDirectory:
      problem = "is a directory, not a YAML file";
      break;
    case internal::RegularFile::kNotRegular:
      problem = "is not a regular file (a device or a pipe?)";
      break;
    case internal::RegularFile::kTooLarge:
      problem = fmt::format("is larger than {} MiB; a wheelhil input file is a few KiB",
                            kMaxFileBytes >> 20);
      break;
    case internal::RegularFile::kCannotRead:
      problem = "cannot be read";
      break;
  }
  Fail(YAML::Mark::null_mark(), "(file)", problem);
}

std::string FieldReader::FieldName(const std::vector<PathStep>& path) {
  std::string name;
  for (const PathStep& step : path) {
    if (step.kind == PathStep::kKey) {
      name = Join(name, step.key);
    } else if (step.kind == PathStep::kIndex) {
      name += fmt::format("[{}]", step.index);
    }
  }
  return name;
}

void FieldReader::CheckNoDuplicateKeys(const YAML::Node& node, std::vector<PathStep>& path,
                                       std::size_t& nodes) const {
  const auto field = [&] {
    const std::string name = FieldName(path);
    return name.empty() ? std::string("(document)") : name;
  };
  if (path.size() > static_cast<std::size_t>(kMaxDepth)) Fail(node, field(), "nested too deeply");
  // Aliases share nodes, so a small file can expand to billions of them ("billion laughs").
  if (++nodes > kMaxNodes) {
    Fail(node, field(),
         fmt::format("the document expands to more than {} nodes (aliases?)", kMaxNodes));
  }
  if (node.IsSequence()) {
    const std::size_t n = node.size();
    for (std::size_t i = 0; i < n; ++i) {
      path.push_back({PathStep::kIndex, {}, i});
      CheckNoDuplicateKeys(node[i], path, nodes);
      path.pop_back();
    }
  } else if (node.IsMap()) {
    std::map<std::string_view, YAML::Mark> seen;
    for (const auto& kv : node) {
      if (kv.first.IsScalar()) {
        const std::string& key = kv.first.Scalar();
        const auto [it, inserted] = seen.emplace(key, kv.first.Mark());
        path.push_back({PathStep::kKey, key, 0});
        if (!inserted) {
          Fail(kv.first, FieldName(path),
               fmt::format("duplicate key (first at line {})", it->second.line + 1));
        }
        CheckNoDuplicateKeys(kv.second, path, nodes);
      } else {
        path.push_back({PathStep::kSame, {}, 0});
        CheckNoDuplicateKeys(kv.second, path, nodes);
      }
      path.pop_back();
    }
  }
}

namespace {

/// YAML 1.2 c-printable: TAB, LF, CR, U+0020..U+007E, U+0085, U+00A0..U+D7FF,
/// U+E000..U+FFFD, U+10000..U+10FFFF. yaml-cpp lets the rest through (a NUL in a scalar came
/// out of it as a byte that is not UTF-8).
bool YamlPrintable(std::uint32_t cp) {
  return cp == 0x09 || cp == 0x0A || cp == 0x0D || (cp >= 0x20 && cp <= 0x7E) || cp == 0x85 ||
         (cp >= 0xA0 && cp <= 0xD7FF) || (cp >= 0xE000 && cp <= 0xFFFD) || cp >= 0x10000;
}

/// Offset of the first byte that does not start a valid UTF-8 sequence (overlong forms,
/// surrogates and code points past U+10FFFF included), or npos; `*cp` is the code point at a
/// valid one that is not YAML-printable (0xFFFFFFFF: invalid UTF-8).
std::size_t FirstInvalidUtf8(std::string_view s, std::uint32_t* bad_cp) {
  *bad_cp = 0xFFFFFFFFu;
  for (std::size_t i = 0; i < s.size();) {
    std::uint32_t cp = 0;
    const std::size_t n = internal::Utf8Sequence(s, i, cp);
    if (n == 0) return i;
    if (!YamlPrintable(cp)) {
      *bad_cp = cp;
      return i;
    }
    i += n;
  }
  return std::string_view::npos;
}

}  // namespace

YAML::Node FieldReader::Parse(const std::string& text) const {
  // YAML is Unicode; wheelhil writes names and values it read into JSON reports, which must be
  // UTF-8. Refused here, once, for every input file.
  std::uint32_t bad_cp = 0;
  if (const std::size_t bad = FirstInvalidUtf8(text, &bad_cp); bad != std::string_view::npos) {
    YAML::Mark at;
    at.pos = static_cast<int>(bad);
    at.line = static_cast<int>(std::count(text.begin(), text.begin() + static_cast<long>(bad), '\n'));
    const std::size_t nl = bad == 0 ? std::string::npos : text.rfind('\n', bad - 1);
    at.column = static_cast<int>(nl == std::string::npos ? bad : bad - nl - 1);
    Fail(at, "(document)",
         bad_cp == 0xFFFFFFFFu
             ? fmt::format("not UTF-8 text (byte 0x{:02X} at offset {})",
                           static_cast<unsigned char>(text[bad]), bad)
             : fmt::format("not YAML text: control character U+{:04X} at offset {}", bad_cp,
                           bad));
  }
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    Fail(e.mark, "(document)", "YAML syntax error: " + e.msg);
  }
  std::size_t nodes = 0;
  std::vector<PathStep> path;
  CheckNoDuplicateKeys(root, path, nodes);
  return root;
}

YAML::Node FieldReader::Get(const YAML::Node& parent, const std::string& key) {
  if (!parent.IsDefined() || !parent.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
  const YAML::Node n = parent[key];
  // A missing key gives a node that throws when used; hand out a harmless undefined one.
  if (!n.IsDefined()) return YAML::Node(YAML::NodeType::Undefined);
  return n;
}

bool FieldReader::Present(const YAML::Node& node) { return node.IsDefined() && !node.IsNull(); }

namespace {
thread_local FieldRecorder* t_recorder = nullptr;
}  // namespace

FieldRecorder* RecordFieldsOnThisThread(FieldRecorder* recorder) {
  FieldRecorder* previous = t_recorder;
  t_recorder = recorder;
  return previous;
}

void FieldReader::Record(std::string_view field, FieldRecorder::Kind kind,
                         std::optional<double> min, std::optional<double> max,
                         std::string_view text) const {
  if (t_recorder != nullptr) t_recorder->Value(file_, field, kind, min, max, text);
}

void FieldReader::CheckKeys(const YAML::Node& map, std::string_view field,
                            const std::set<std::string>& allowed) const {
  if (t_recorder != nullptr) t_recorder->Keys(file_, field, allowed);
  const std::string_view name = field.empty() ? "(document)" : field;
  if (!map.IsDefined() || !map.IsMap()) Fail(map, name, "must be a mapping");
  section_mark_ = map.Mark();
  section_field_ = std::string(field);
  for (const auto& kv : map) {
    if (!kv.first.IsScalar()) Fail(kv.first, name, "a key must be a plain name");
    const std::string& key = kv.first.Scalar();
    if (allowed.count(key) != 0) continue;
    std::string list;
    for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
    Fail(kv.first, Join(field, key), fmt::format("unknown key (allowed: {})", list));
  }
}

double FieldReader::ToNumber(const YAML::Node& node, std::string_view field) const {
  Record(field, FieldRecorder::Kind::kNumber);
  return NumberValue(node, field);
}

double FieldReader::NumberValue(const YAML::Node& node, std::string_view field) const {
  if (!node.IsDefined() || !node.IsScalar()) Fail(node, field, "must be a number");
  double v = 0;
  if (!YAML::convert<double>::decode(node, v)) {
    Fail(node, field, fmt::format("'{}' is not a number", node.Scalar()));
  }
  if (!std::isfinite(v)) Fail(node, field, "must be finite");
  return v;
}

double FieldReader::ToNumber(const YAML::Node& node, std::string_view field, double min,
                             double max) const {
  Record(field, FieldRecorder::Kind::kNumber, min, max);
  const double v = NumberValue(node, field);
  if (v < min || v > max) Fail(node, field, fmt::format("({}) must be in [{}, {}]", v, min, max));
  return v;
}

long long FieldReader::ToInteger(const YAML::Node& node, std::string_view field, long long min,
                                 long long max) const {
  Record(field, FieldRecorder::Kind::kInteger, static_cast<double>(min), static_cast<double>(max));
  if (!node.IsDefined() || !node.IsScalar()) Fail(node, field, "must be an integer");
  long long v = 0;
  if (!YAML::convert<long long>::decode(node, v)) {
    Fail(node, field, fmt::format("'{}' is not an integer", node.Scalar()));
  }
  if (v < min || v > max) Fail(node, field, fmt::format("({}) must be in [{}, {}]", v, min, max));
  return v;
}

void FieldReader::CheckCount(const YAML::Node& list, std::string_view field,
                             std::size_t max) const {
  if (list.IsDefined() && list.size() > max) {
    Fail(list, field, fmt::format("{} entries; at most {} are supported", list.size(), max));
  }
}

bool FieldReader::ToBool(const YAML::Node& node, std::string_view field) const {
  Record(field, FieldRecorder::Kind::kBool);
  bool v = false;
  if (!node.IsDefined() || !node.IsScalar() || !YAML::convert<bool>::decode(node, v)) {
    Fail(node, field, "must be true or false");
  }
  return v;
}

std::string FieldReader::ToString(const YAML::Node& node, std::string_view field) const {
  Record(
      field, FieldRecorder::Kind::kString, {}, {},
      node.IsDefined() && node.IsScalar() ? std::string_view(node.Scalar()) : std::string_view());
  if (!node.IsDefined() || !node.IsScalar()) Fail(node, field, "must be a string");
  return node.Scalar();
}

void FieldReader::DeclareKeys(std::string_view field, const std::set<std::string>& keys) const {
  if (t_recorder != nullptr) t_recorder->Keys(file_, field, keys);
}

std::string FieldReader::KeyName(const YAML::Node& key, std::string_view field) const {
  if (t_recorder != nullptr) t_recorder->OpenMap(file_, field);
  if (!key.IsDefined() || !key.IsScalar()) Fail(key, field, "must be a string");
  return key.Scalar();
}

YAML::Node FieldReader::Required(const YAML::Node& parent, const std::string& key,
                                 std::string_view field) const {
  const YAML::Node n = Get(parent, key);
  if (!Present(n)) FailKey(parent, key, field, "is required");
  return n;
}

double FieldReader::Number(const YAML::Node& parent, const std::string& key,
                           std::string_view prefix, double min, double max,
                           std::optional<double> def) const {
  const std::string field = Join(prefix, key);
  if (def && !Present(Get(parent, key))) return *def;
  return ToNumber(Required(parent, key, field), field, min, max);
}

long long FieldReader::Integer(const YAML::Node& parent, const std::string& key,
                               std::string_view prefix, long long min, long long max,
                               std::optional<long long> def) const {
  const std::string field = Join(prefix, key);
  if (def && !Present(Get(parent, key))) return *def;
  return ToInteger(Required(parent, key, field), field, min, max);
}

bool FieldReader::Bool(const YAML::Node& parent, const std::string& key, std::string_view prefix,
                       std::optional<bool> def) const {
  const std::string field = Join(prefix, key);
  if (def && !Present(Get(parent, key))) return *def;
  return ToBool(Required(parent, key, field), field);
}

std::string FieldReader::String(const YAML::Node& parent, const std::string& key,
                                std::string_view prefix, std::optional<std::string> def) const {
  const std::string field = Join(prefix, key);
  if (def && !Present(Get(parent, key))) return *def;
  return ToString(Required(parent, key, field), field);
}

}  // namespace wheelhil::bus::yaml
