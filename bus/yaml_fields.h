#pragma once
/// Located reading of YAML input files, one error format for every file wheelhil reads
/// (scenario, platform, campaign, firmware config): std::invalid_argument
///     "file:line:col: field: problem"
/// with the 1-based line and column of the offending node, or file:0:0 when there is none (a
/// file that cannot be read). `field` is the dotted path from the document root
/// (`sensors.encoders.nodes[1].node_id`); "(document)" and "(file)" name the whole file.
///
/// This is in bus/ although it has nothing to do with CAN: bus/ is the one library every program
/// links, and the firmware, which may depend on bus/ only, reads a YAML config too.
///
/// Nothing here hands out a yaml-cpp node that throws when used: Get() returns an undefined node
/// for a missing key where yaml-cpp's const operator[] returns one that throws InvalidNode on
/// IsMap(), Mark(), as<>(). Guard() turns any yaml-cpp exception a loader still lets escape into
/// the same std::invalid_argument, so a malformed file is an input error, never an abort.
/// Thread-compatible.

#include <cstddef>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include <yaml-cpp/yaml.h>

namespace wheelhil::bus::yaml {

/// Sees what every FieldReader on the calling thread checks: the loaders' own definition of
/// their files, from which `wheelhil schema` writes JSON Schemas. `field` is the dotted path
/// as in messages (list indices included); `file` the reader's file().
class FieldRecorder {
 public:
  enum class Kind { kNumber, kInteger, kBool, kString };
  virtual ~FieldRecorder() = default;
  /// A mapping at `field` whose keys must be among `allowed`.
  virtual void Keys(const std::string& file, std::string_view field,
                    const std::set<std::string>& allowed) = 0;
  /// A mapping at `field` whose keys are names of the user's choosing (KeyName).
  virtual void OpenMap(const std::string& file, std::string_view field) = 0;
  /// A scalar at `field`; `min`/`max` when the reader checked a range; `text`: a string's value
  /// as written (a `type:` or `kind:` that selects which keys its mapping has).
  virtual void Value(const std::string& file, std::string_view field, Kind kind,
                     std::optional<double> min, std::optional<double> max,
                     std::string_view text) = 0;
};

/// Installs `recorder` for the calling thread (nullptr: none); returns the previous one.
FieldRecorder* RecordFieldsOnThisThread(FieldRecorder* recorder);

class FieldReader {
 public:
  /// `file` names the input in every message (and is what ReadFile opens).
  explicit FieldReader(std::string file);

  const std::string& file() const noexcept { return file_; }

  /// "prefix.key", or just the key when `prefix` is empty.
  static std::string Join(std::string_view prefix, std::string_view key);

  /// "file:line:col" of `node`; "file:0:0" for a node without a position (undefined, or built
  /// in code rather than parsed).
  std::string Where(const YAML::Node& node) const;
  std::string Where(const YAML::Mark& mark) const;

  /// Throws std::invalid_argument "Where(at): field: problem".
  [[noreturn]] void Fail(const YAML::Node& at, std::string_view field,
                         std::string_view problem) const;
  [[noreturn]] void Fail(const YAML::Mark& at, std::string_view field,
                         std::string_view problem) const;
  /// Fails at parent[key] when the key is there, else at `parent` (a missing key has no
  /// position of its own).
  [[noreturn]] void FailKey(const YAML::Node& parent, const std::string& key,
                            std::string_view field, std::string_view problem) const;

  /// Largest input file read (a scenario is a few KiB; /dev/zero must not fill the memory).
  static constexpr std::size_t kMaxFileBytes = std::size_t{16} << 20;
  /// Deepest nesting of mappings and sequences accepted.
  static constexpr int kMaxDepth = 64;
  /// Most nodes a document may hold once its aliases are expanded.
  static constexpr std::size_t kMaxNodes = 1'000'000;

  /// The whole text of file(); fails "file:0:0: (file): ..." when it is missing, a directory, not
  /// a regular file (/dev/zero, a pipe), unreadable or larger than kMaxFileBytes.
  std::string ReadFile() const;
  /// The document in `text`; a syntax error fails "(document): YAML syntax error: ..." at its
  /// position, a mapping that repeats a key fails "field.key: duplicate key (first at line N)"
  /// at the repetition (yaml-cpp would keep the first silently), nesting deeper than kMaxDepth
  /// fails "nested too deeply", more than kMaxNodes nodes after alias expansion fails too.
  YAML::Node Parse(const std::string& text) const;

  /// Runs `read` and returns what it returns. A yaml-cpp exception escaping it fails at the
  /// exception's own position, or, when it has none (InvalidNode), at the mapping last passed
  /// to CheckKeys, named by that mapping's field: the section being read.
  template <typename Read>
  auto Guard(Read&& read) const -> decltype(read()) {
    try {
      return read();
    } catch (const YAML::Exception& e) {
      FailYaml(e);
    }
  }

  /// `parent[key]`, or an undefined node when `parent` is not a mapping or has no `key`.
  static YAML::Node Get(const YAML::Node& parent, const std::string& key);
  /// The node holds a value: defined and not null (`key:` and `key: ~` are absent).
  static bool Present(const YAML::Node& node);

  /// Fails unless `map` is a mapping whose keys are all in `allowed`: "field: must be a mapping"
  /// at the node, "field.key: unknown key (allowed: ...)" at the key.
  void CheckKeys(const YAML::Node& map, std::string_view field,
                 const std::set<std::string>& allowed) const;
  /// Keys of the mapping at `field` that a step before CheckKeys reads and removes (a robot
  /// description's): told to the FieldRecorder only.
  void DeclareKeys(std::string_view field, const std::set<std::string>& keys) const;

  // A node that is present, as a value; each fails at the node, naming `field`.
  /// A finite number.
  double ToNumber(const YAML::Node& node, std::string_view field) const;
  /// A finite number in [min, max]: "(v) must be in [min, max]".
  double ToNumber(const YAML::Node& node, std::string_view field, double min, double max) const;
  /// An integer (decimal, 0x hexadecimal or 0o octal, as yaml-cpp reads them) in [min, max].
  long long ToInteger(const YAML::Node& node, std::string_view field, long long min,
                      long long max) const;
  /// Fails "field: N entries; at most `max` are supported" unless `list` has at most `max`.
  void CheckCount(const YAML::Node& list, std::string_view field, std::size_t max) const;
  /// true/false (and the other spellings yaml-cpp reads as booleans: yes/no, on/off).
  bool ToBool(const YAML::Node& node, std::string_view field) const;
  /// Any scalar, as written.
  std::string ToString(const YAML::Node& node, std::string_view field) const;
  /// A key of the mapping at `field` whose keys are the user's names (a wheel name, a
  /// kinematic parameter): ToString, recorded as such a mapping rather than as a value.
  std::string KeyName(const YAML::Node& key, std::string_view field) const;

  // parent[key], field Join(prefix, key). Absent (no key, or null) gives `def`, or fails
  // "field: is required" at `parent` when there is no default.
  double Number(const YAML::Node& parent, const std::string& key, std::string_view prefix,
                double min, double max, std::optional<double> def = std::nullopt) const;
  long long Integer(const YAML::Node& parent, const std::string& key, std::string_view prefix,
                    long long min, long long max,
                    std::optional<long long> def = std::nullopt) const;
  bool Bool(const YAML::Node& parent, const std::string& key, std::string_view prefix,
            std::optional<bool> def = std::nullopt) const;
  std::string String(const YAML::Node& parent, const std::string& key, std::string_view prefix,
                     std::optional<std::string> def = std::nullopt) const;

 private:
  [[noreturn]] void FailYaml(const YAML::Exception& e) const;
  double NumberValue(const YAML::Node& node, std::string_view field) const;
  void Record(std::string_view field, FieldRecorder::Kind kind, std::optional<double> min = {},
              std::optional<double> max = {}, std::string_view text = {}) const;
  // One step from the document to a node: a key, an index, or a complex key's value (the
  // field name stays its parent's). The name is formatted only for a message: the walk over a
  // document of a million nodes must not build a million strings.
  struct PathStep {
    enum Kind { kKey, kIndex, kSame } kind;
    std::string_view key;
    std::size_t index;
  };
  static std::string FieldName(const std::vector<PathStep>& path);
  void CheckNoDuplicateKeys(const YAML::Node& node, std::vector<PathStep>& path,
                            std::size_t& nodes) const;
  YAML::Node Required(const YAML::Node& parent, const std::string& key,
                      std::string_view field) const;

  std::string file_;
  // The mapping CheckKeys saw last: where an exception without a position is reported.
  mutable YAML::Mark section_mark_ = YAML::Mark::null_mark();
  mutable std::string section_field_;
};

}  // namespace wheelhil::bus::yaml
