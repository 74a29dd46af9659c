#pragma once
/// A CAN database (Vector DBC) loaded from the files in bus/dbc/, the one source of truth for
/// every frame wheelhil puts on a bus. Parses the subset real files use: VERSION, NS_ (skipped),
/// BS_, BU_, BO_, SG_ (Intel @1 / Motorola @0, signed/unsigned, factor/offset/min/max/unit,
/// receivers, one multiplexer switch `M` with `m<n>` signals), VAL_, VAL_TABLE_, CM_ (global,
/// BU_, BO_, SG_; multi-line strings), BA_DEF_, BA_DEF_DEF_, BA_ (GenMsgCycleTime on messages
/// becomes DbcMessage::cycle_time_ms), SIG_VALTYPE_ (IEEE float/double signals). Other known
/// keywords (BO_TX_BU_, EV_, SIG_GROUP_, BA_DEF_REL_, SG_MUL_VAL_, ...) are skipped up to their
/// ';'. Extended ids have bit 31 set in the BO_ id; the VECTOR__INDEPENDENT_SIG_MSG
/// pseudo-message (0xC0000000) is dropped.
///
/// Loading validates what the codec relies on: every signal lies inside its message's length,
/// lengths are 1..64 bits (32/64 for float signals), factors are finite and non-zero, names are
/// unique, `m<n>` signals have a multiplexer, no two signals that can be in one frame share a
/// bit. A leading UTF-8 byte-order mark is skipped. Errors throw std::invalid_argument reading
/// "<file>:<line>: <problem>". A loaded database is immutable and safe to share between threads.
/// Encoding and decoding live in bus/dbc_codec.h.

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace wheelhil::bus {

enum class DbcValueType : std::uint8_t {
  kInteger,  ///< Two's complement or unsigned integer of `length` bits.
  kFloat32,  ///< IEEE 754 single (SIG_VALTYPE_ 1), length 32.
  kFloat64,  ///< IEEE 754 double (SIG_VALTYPE_ 2), length 64.
};

/// One signal. physical = raw * factor + offset. `start_bit` is as written in the file: for
/// Intel (little_endian) the LSB, for Motorola the MSB in DBC "sawtooth" numbering (bit 7 of
/// byte 0 is 7, bit 0 of byte 1 is 8).
struct DbcSignal {
  std::string name;
  int start_bit = 0;
  int length = 1;
  bool little_endian = true;  ///< @1 Intel; false: @0 Motorola.
  bool is_signed = false;     ///< @..- two's complement.
  DbcValueType value_type = DbcValueType::kInteger;
  double factor = 1.0;
  double offset = 0.0;
  double minimum = 0.0;  ///< Physical range from the file; [0|0] means "not given".
  double maximum = 0.0;
  std::string unit;
  std::vector<std::string> receivers;
  bool is_multiplexer = false;                      ///< The message's multiplexer switch (`M`).
  std::optional<int> multiplex_value;               ///< Set for `m<n>` signals.
  std::map<std::int64_t, std::string> value_names;  ///< VAL_: raw value -> name.
  std::string comment;
  /// BA_ values of the signal (GenSigStartValue, ...) or their BA_DEF_DEF_ defaults, as
  /// written; an ENUM attribute's value is its string, not its index.
  std::map<std::string, std::string, std::less<>> attributes;

  /// An integer whose physical value is its raw value (factor 1, offset 0): what a counter or
  /// a cycle number must be.
  bool IsRawInteger() const {
    return value_type == DbcValueType::kInteger && factor == 1.0 && offset == 0.0;
  }
};

/// One message (frame). `id` has no flag bits; `length` is the DLC in bytes (0..64).
struct DbcMessage {
  std::uint32_t id = 0;
  bool extended = false;
  std::string name;
  int length = 0;
  std::string sender;
  std::vector<DbcSignal> signals;
  std::optional<int> cycle_time_ms;  ///< BA_ "GenMsgCycleTime" (or its non-zero default).
  std::string comment;
  /// BA_ values of this message by attribute name, as written (strings unquoted), or their
  /// BA_DEF_DEF_ defaults; an ENUM attribute's value is its string (GenMsgSendType "Cyclic"),
  /// whatever index the file wrote.
  std::map<std::string, std::string, std::less<>> attributes;

  const DbcSignal* FindSignal(std::string_view name) const;
  /// The multiplexer switch signal, or nullptr when the message is not multiplexed.
  const DbcSignal* multiplexer() const;
};

class DbcDatabase {
 public:
  /// Largest DBC file LoadFile reads: the largest real ones are tens of MiB; a generated 100 MB
  /// one loads in a few seconds.
  static constexpr std::size_t kMaxFileBytes = std::size_t{128} << 20;
  /// Reads and parses `path`; throws std::invalid_argument ("path:line: problem"), also for a
  /// path that is not a regular file ("path:0: is a directory, not a DBC file", "... is not a
  /// regular file (a device or a pipe?)") or larger than kMaxFileBytes.
  static DbcDatabase LoadFile(const std::string& path);
  /// Parses DBC text; `source_name` prefixes error messages.
  static DbcDatabase Parse(std::string_view text, const std::string& source_name);

  const DbcMessage* FindMessage(std::uint32_t id, bool extended) const;
  const DbcMessage* FindMessage(std::string_view name) const;
  const std::vector<DbcMessage>& messages() const { return messages_; }
  const std::vector<std::string>& nodes() const { return nodes_; }
  const std::string& version() const { return version_; }
  const std::string& comment() const { return comment_; }
  /// VAL_TABLE_ definitions by table name.
  const std::map<std::string, std::map<std::int64_t, std::string>, std::less<>>& value_tables()
      const {
    return value_tables_;
  }

 private:
  friend class DbcParser;
  void BuildIndex();

  std::string version_;
  std::string comment_;
  std::vector<std::string> nodes_;
  std::vector<DbcMessage> messages_;
  std::map<std::string, std::map<std::int64_t, std::string>, std::less<>> value_tables_;
  std::unordered_map<std::uint64_t, std::size_t> by_id_;
  std::map<std::string, std::size_t, std::less<>> by_name_;
};

}  // namespace wheelhil::bus
