// One file on purpose (~700 lines): the DBC grammar (BU_, BO_, SG_, VAL_, BA_DEF_, BA_, ...)
// is read by one tokenizer and one statement dispatcher; each statement's reader is short.
#include "bus/dbc.h"

#include <fmt/format.h>

#include <algorithm>
#include <bitset>
#include <charconv>
#include <cmath>
#include <set>
#include <stdexcept>
#include <unordered_map>

#include "bus/internal/input_file.h"

namespace wheelhil::bus {
namespace {

constexpr std::uint32_t kExtendedIdFlag = 0x80000000u;
constexpr std::uint32_t kIndependentSignalsId = 0xC0000000u;  // VECTOR__INDEPENDENT_SIG_MSG

// Keywords whose statements we do not need; they are skipped up to their terminating ';'.
const std::set<std::string_view>& IgnoredKeywords() {
  static const std::set<std::string_view> k = {
      "BO_TX_BU_",        "EV_",        "ENVVAR_DATA_",  "SGTYPE_",
      "SGTYPE_VAL_",      "SIG_GROUP_", "SIG_TYPE_REF_", "BA_DEF_REL_",
      "BA_DEF_DEF_REL_",  "BA_REL_",    "BA_SGTYPE_",    "BA_DEF_SGTYPE_",
      "BU_SG_REL_",       "BU_EV_REL_", "BU_BO_REL_",    "SG_MUL_VAL_",
      "CAT_DEF_",         "CAT_",       "FILTER",        "NS_DESC_",
      "SIGTYPE_VALTYPE_", "EV_DATA_",   "VAL_TABLE_REF_"};
  return k;
}

bool IsIdentStart(char c) { return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || c == '_'; }
bool IsIdentChar(char c) { return IsIdentStart(c) || (c >= '0' && c <= '9'); }

/// Motorola MSB position in "linear" numbering (byte 0 bit 7 = 0, byte 0 bit 0 = 7, byte 1
/// bit 7 = 8, ...).
int MotorolaLinear(int sawtooth_bit) { return (sawtooth_bit / 8) * 8 + 7 - sawtooth_bit % 8; }

}  // namespace

// Recursive-descent parser over the raw text with line tracking. Not exposed in the header
// beyond the friend declaration.
class DbcParser {
 public:
  // A leading byte-order mark (Windows tools write one) is not part of the text.
  DbcParser(std::string_view text, const std::string& source)
      : s_(internal::SkipUtf8Bom(text)), source_(source) {}

  DbcDatabase Run() {
    for (;;) {
      SkipSpace();
      if (AtEnd()) break;
      statement_line_ = line_;
      if (!IsIdentStart(s_[pos_])) Fail(fmt::format("unexpected character '{}'", s_[pos_]));
      const std::string_view kw = Ident();
      if (kw == "VERSION") {
        db_.version_ = String();
      } else if (kw == "NS_") {
        SkipNamespaceBlock();
      } else if (kw == "BS_") {
        Expect(':');
        SkipToEndOfLine();
      } else if (kw == "BU_") {
        Expect(':');
        while (IdentOnLine()) db_.nodes_.emplace_back(last_ident_);
      } else if (kw == "BO_") {
        Message();
      } else if (kw == "SG_") {
        Signal();
      } else if (kw == "VAL_TABLE_") {
        ValueTable();
      } else if (kw == "VAL_") {
        ValueDescriptions();
      } else if (kw == "CM_") {
        Comment();
      } else if (kw == "BA_DEF_") {
        AttributeDefinition();
      } else if (kw == "BA_DEF_DEF_") {
        AttributeDefault();
      } else if (kw == "BA_") {
        Attribute();
      } else if (kw == "SIG_VALTYPE_") {
        SignalValueType();
      } else if (IgnoredKeywords().count(kw) != 0) {
        SkipStatement();
      } else {
        Fail(fmt::format("unknown keyword '{}'", kw));
      }
    }
    Finish();
    return std::move(db_);
  }

 private:
  [[noreturn]] void Fail(std::string_view problem) const { FailAt(statement_line_, problem); }
  [[noreturn]] void FailAt(int line, std::string_view problem) const {
    throw std::invalid_argument(fmt::format("{}:{}: {}", source_, line, problem));
  }

  bool AtEnd() const { return pos_ >= s_.size(); }
  char Peek() const { return AtEnd() ? '\0' : s_[pos_]; }
  void Advance() {
    if (s_[pos_] == '\n') {
      ++line_;
      line_start_ = pos_ + 1;
    }
    ++pos_;
  }
  void SkipSpace() {
    while (!AtEnd()) {
      const char c = s_[pos_];
      if (c == ' ' || c == '\t' || c == '\r' || c == '\n') {
        Advance();
      } else if (c == '/' && pos_ + 1 < s_.size() && s_[pos_ + 1] == '/') {
        while (!AtEnd() && s_[pos_] != '\n') Advance();  // `//` comment (some tools write them)
      } else {
        break;
      }
    }
  }
  void SkipBlanks() {  // within a line
    while (!AtEnd() && (s_[pos_] == ' ' || s_[pos_] == '\t' || s_[pos_] == '\r')) Advance();
  }
  void SkipToEndOfLine() {
    while (!AtEnd() && s_[pos_] != '\n') Advance();
  }

  std::string_view Ident() {
    SkipSpace();
    if (AtEnd() || !IsIdentStart(s_[pos_])) {
      Fail(AtEnd() ? "unexpected end of file, expected a name"
                   : fmt::format("expected a name, found '{}'", s_[pos_]));
    }
    const std::size_t begin = pos_;
    while (!AtEnd() && IsIdentChar(s_[pos_])) Advance();
    return s_.substr(begin, pos_ - begin);
  }
  /// Reads the next name on the current line (names may be separated by ',' or blanks).
  bool IdentOnLine() {
    SkipBlanks();
    while (Peek() == ',') {
      Advance();
      SkipBlanks();
    }
    if (AtEnd() || Peek() == '\n') return false;
    last_ident_ = Ident();
    return true;
  }

  void Expect(char c) {
    SkipSpace();
    if (AtEnd()) Fail(fmt::format("unexpected end of file, expected '{}'", c));
    if (s_[pos_] != c) Fail(fmt::format("expected '{}', found '{}'", c, s_[pos_]));
    Advance();
  }
  bool Accept(char c) {
    SkipSpace();
    if (Peek() != c) return false;
    Advance();
    return true;
  }

  std::string String() {
    SkipSpace();
    if (Peek() != '"') Fail("expected a quoted string");
    const int start_line = line_;
    Advance();
    std::string out;
    for (;;) {
      if (AtEnd()) FailAt(start_line, "unterminated string");
      const char c = s_[pos_];
      if (c == '"') {
        Advance();
        return out;
      }
      if (c == '\\' && pos_ + 1 < s_.size() && (s_[pos_ + 1] == '"' || s_[pos_ + 1] == '\\')) {
        Advance();
        out += s_[pos_];
        Advance();
        continue;
      }
      out += c;
      Advance();
    }
  }

  std::string_view NumberToken() {
    SkipSpace();
    const std::size_t begin = pos_;
    while (!AtEnd()) {
      const char c = s_[pos_];
      const bool exp_sign =
          (c == '+' || c == '-') && pos_ > begin && (s_[pos_ - 1] == 'e' || s_[pos_ - 1] == 'E');
      if ((c >= '0' && c <= '9') || c == '.' || c == 'e' || c == 'E' || exp_sign ||
          ((c == '-' || c == '+') && pos_ == begin)) {
        Advance();
      } else {
        break;
      }
    }
    if (begin == pos_) {
      Fail(AtEnd() ? "unexpected end of file, expected a number"
                   : fmt::format("expected a number, found '{}'", s_[pos_]));
    }
    return s_.substr(begin, pos_ - begin);
  }
  double Double() {
    std::string_view t = NumberToken();
    const std::string_view original = t;
    if (!t.empty() && t[0] == '+') t.remove_prefix(1);
    double v = 0;
    const auto r = std::from_chars(t.data(), t.data() + t.size(), v);
    if (r.ec != std::errc() || r.ptr != t.data() + t.size() || !std::isfinite(v)) {
      Fail(fmt::format("'{}' is not a number", original));
    }
    return v;
  }
  std::int64_t Int() {
    std::string_view t = NumberToken();
    const std::string_view original = t;
    if (!t.empty() && t[0] == '+') t.remove_prefix(1);
    std::int64_t v = 0;
    auto r = std::from_chars(t.data(), t.data() + t.size(), v);
    if (r.ec == std::errc::result_out_of_range && !t.empty() && t[0] != '-') {
      std::uint64_t u = 0;  // VAL_ tables of 64-bit unsigned signals
      r = std::from_chars(t.data(), t.data() + t.size(), u);
      v = static_cast<std::int64_t>(u);
    }
    if (r.ec != std::errc() || r.ptr != t.data() + t.size()) {
      Fail(fmt::format("'{}' is not an integer", original));
    }
    return v;
  }
  std::uint32_t RawMessageId() {
    const std::int64_t v = Int();
    if (v < 0 || v > 0xFFFFFFFFLL) Fail(fmt::format("message id {} out of range", v));
    return static_cast<std::uint32_t>(v);
  }

  void SkipStatement() {
    for (;;) {
      SkipSpace();
      if (AtEnd()) Fail("unexpected end of file, expected ';'");
      if (s_[pos_] == '"') {
        (void)String();
      } else if (s_[pos_] == ';') {
        Advance();
        return;
      } else {
        Advance();
      }
    }
  }

  // NS_ : followed by keyword names (usually indented); ends before BS_, BU_ or BO_, which
  // never appear in the list.
  void SkipNamespaceBlock() {
    Expect(':');
    for (;;) {
      SkipSpace();
      if (AtEnd()) return;
      const std::size_t save_pos = pos_, save_start = line_start_;
      const int save_line = line_;
      const std::string_view name = Ident();
      if (name == "BS_" || name == "BU_" || name == "BO_") {
        pos_ = save_pos;
        line_start_ = save_start;
        line_ = save_line;
        return;
      }
    }
  }

  // --- messages and signals -------------------------------------------------------------

  // Indexed: a large database has 10^5 messages, each named again by its CM_, BA_, VAL_.
  static std::uint64_t IdKey(std::uint32_t id, bool extended) {
    return static_cast<std::uint64_t>(id) | (extended ? (1ULL << 32) : 0);
  }
  DbcMessage* MessageById(std::uint32_t raw_id) {
    const auto it =
        message_by_id_.find(IdKey(raw_id & 0x1FFFFFFFu, (raw_id & kExtendedIdFlag) != 0));
    return it == message_by_id_.end() ? nullptr : &db_.messages_[it->second];
  }
  DbcMessage& RequireMessage(std::uint32_t raw_id) {
    DbcMessage* m = MessageById(raw_id);
    if (!m) Fail(fmt::format("message id {} is not defined by a BO_", raw_id));
    return *m;
  }
  DbcSignal& RequireSignal(std::uint32_t raw_id, std::string_view name) {
    DbcMessage& m = RequireMessage(raw_id);
    const std::size_t i = static_cast<std::size_t>(&m - db_.messages_.data());
    const auto it = signal_by_name_[i].find(std::string(name));
    if (it == signal_by_name_[i].end()) {
      Fail(fmt::format("message {} has no signal '{}'", m.name, name));
    }
    return m.signals[it->second];
  }

  void Message() {
    const std::uint32_t raw = RawMessageId();
    const std::string name(Ident());
    Expect(':');
    const std::int64_t length = Int();
    const std::string sender(Ident());
    current_message_ = -1;
    if (raw == kIndependentSignalsId) {  // pseudo-message, its SG_ lines are dropped
      skipping_message_ = true;
      return;
    }
    skipping_message_ = false;
    const bool extended = (raw & kExtendedIdFlag) != 0;
    const std::uint32_t id = raw & ~kExtendedIdFlag;
    if (raw & 0x40000000u) Fail(fmt::format("message {}: id {} has bit 30 set", name, raw));
    if (id > (extended ? 0x1FFFFFFFu : 0x7FFu)) {
      Fail(fmt::format("message {}: id 0x{:X} does not fit a {} identifier", name, id,
                       extended ? "29-bit" : "11-bit (set bit 31 for extended ids)"));
    }
    if (length < 0 || length > 64) {
      Fail(fmt::format("message {}: length {} must be 0..64 bytes", name, length));
    }
    if (MessageById(raw)) Fail(fmt::format("message {}: id {} defined twice", name, raw));
    if (!message_names_.insert(name).second) {
      Fail(fmt::format("message name '{}' defined twice", name));
    }
    message_by_id_.emplace(IdKey(id, extended), db_.messages_.size());
    signal_by_name_.emplace_back();
    has_multiplexer_.push_back(false);
    DbcMessage m;
    m.id = id;
    m.extended = extended;
    m.name = name;
    m.length = static_cast<int>(length);
    m.sender = sender;
    db_.messages_.push_back(std::move(m));
    message_lines_.push_back(statement_line_);
    current_message_ = static_cast<int>(db_.messages_.size()) - 1;
  }

  void Signal() {
    if (current_message_ < 0 && !skipping_message_) Fail("SG_ outside a BO_ message");
    DbcSignal sig;
    sig.name = std::string(Ident());
    SkipSpace();
    if (Peek() == 'M' || Peek() == 'm') {
      const std::string_view mux = Ident();
      if (mux == "M") {
        sig.is_multiplexer = true;
      } else if (mux.size() > 1 && mux[0] == 'm') {
        std::string_view digits = mux.substr(1);
        if (digits.back() == 'M') {
          Fail(fmt::format("signal {}: extended multiplexing ('{}') is not supported", sig.name,
                           mux));
        }
        int v = 0;
        const auto r = std::from_chars(digits.data(), digits.data() + digits.size(), v);
        if (r.ec != std::errc() || r.ptr != digits.data() + digits.size() || v < 0) {
          Fail(fmt::format("signal {}: bad multiplexer indicator '{}'", sig.name, mux));
        }
        sig.multiplex_value = v;
      } else {
        Fail(fmt::format("signal {}: bad multiplexer indicator '{}'", sig.name, mux));
      }
    }
    Expect(':');
    const std::int64_t start = Int();
    Expect('|');
    const std::int64_t length = Int();
    Expect('@');
    SkipSpace();
    const char order = Peek();
    if (order != '0' && order != '1')
      Fail(fmt::format("signal {}: byte order must be @0 or @1", sig.name));
    Advance();
    const char sign = Peek();
    if (sign != '+' && sign != '-') {
      Fail(fmt::format("signal {}: sign must be '+' or '-' after @{}", sig.name, order));
    }
    Advance();
    Expect('(');
    sig.factor = Double();
    Expect(',');
    sig.offset = Double();
    Expect(')');
    Expect('[');
    sig.minimum = Double();
    Expect('|');
    sig.maximum = Double();
    Expect(']');
    sig.unit = String();
    while (IdentOnLine()) sig.receivers.emplace_back(last_ident_);

    if (skipping_message_) return;
    sig.little_endian = order == '1';
    sig.is_signed = sign == '-';
    if (length < 1 || length > 64)
      Fail(fmt::format("signal {}: length {} must be 1..64", sig.name, length));
    if (start < 0 || start >= 512)
      Fail(fmt::format("signal {}: start bit {} out of range", sig.name, start));
    sig.start_bit = static_cast<int>(start);
    sig.length = static_cast<int>(length);
    if (sig.factor == 0.0) Fail(fmt::format("signal {}: factor must not be 0", sig.name));
    DbcMessage& m = db_.messages_[static_cast<std::size_t>(current_message_)];
    const int bits = m.length * 8;
    int first = 0, last = 0;  // linear bit range used
    if (sig.little_endian) {
      first = sig.start_bit;
      last = sig.start_bit + sig.length - 1;
    } else {
      first = MotorolaLinear(sig.start_bit);
      last = first + sig.length - 1;
    }
    if (last >= bits) {
      Fail(fmt::format("signal {}: {}|{}@{} does not fit message {} of {} bytes", sig.name,
                       sig.start_bit, sig.length, order, m.name, m.length));
    }
    (void)first;
    const auto current = static_cast<std::size_t>(current_message_);
    if (!signal_by_name_[current].emplace(sig.name, m.signals.size()).second) {
      Fail(fmt::format("signal {} defined twice in message {}", sig.name, m.name));
    }
    if (sig.is_multiplexer) {
      if (has_multiplexer_[current]) {
        Fail(fmt::format("message {}: second multiplexer switch {} (only one is supported)", m.name,
                         sig.name));
      }
      has_multiplexer_[current] = true;
    }
    m.signals.push_back(std::move(sig));
  }

  // --- value descriptions, comments -------------------------------------------------------

  std::map<std::int64_t, std::string> ValuePairs() {
    std::map<std::int64_t, std::string> values;
    for (;;) {
      SkipSpace();
      if (Accept(';')) return values;
      if (AtEnd()) Fail("unexpected end of file, expected ';'");
      const std::int64_t v = Int();
      values[v] = String();
    }
  }

  void ValueTable() {
    const std::string name(Ident());
    db_.value_tables_[name] = ValuePairs();
  }

  void ValueDescriptions() {
    SkipSpace();
    if (IsIdentStart(Peek())) {  // VAL_ <env var> ... : environment variables, not needed
      SkipStatement();
      return;
    }
    const std::uint32_t raw = RawMessageId();
    const std::string name(Ident());
    auto values = ValuePairs();
    if (raw == kIndependentSignalsId) return;
    RequireSignal(raw, name).value_names = std::move(values);
  }

  void Comment() {
    SkipSpace();
    if (Peek() == '"') {
      db_.comment_ = String();
      Expect(';');
      return;
    }
    const std::string_view kind = Ident();
    if (kind == "BU_") {
      (void)Ident();
      (void)String();
    } else if (kind == "BO_") {
      const std::uint32_t raw = RawMessageId();
      std::string text = String();
      if (raw != kIndependentSignalsId) RequireMessage(raw).comment = std::move(text);
    } else if (kind == "SG_") {
      const std::uint32_t raw = RawMessageId();
      const std::string name(Ident());
      std::string text = String();
      if (raw != kIndependentSignalsId) RequireSignal(raw, name).comment = std::move(text);
    } else if (kind == "EV_") {
      (void)Ident();
      (void)String();
    } else {
      Fail(fmt::format("CM_ of unknown object type '{}'", kind));
    }
    Expect(';');
  }

  // --- attributes --------------------------------------------------------------------------

  struct AttributeDef {
    std::string object;  // "", "BU_", "BO_", "SG_", "EV_"
    std::string type;    // INT HEX FLOAT STRING ENUM
    std::vector<std::string> enum_values;
    std::string default_value;
  };

  void AttributeDefinition() {
    AttributeDef def;
    SkipSpace();
    if (Peek() != '"') def.object = std::string(Ident());
    const std::string name = String();
    def.type = std::string(Ident());
    if (def.type == "INT" || def.type == "HEX" || def.type == "FLOAT") {
      (void)Double();
      (void)Double();
    } else if (def.type == "ENUM") {
      SkipSpace();
      while (Peek() == '"') {
        def.enum_values.push_back(String());
        if (!Accept(',')) break;
        SkipSpace();
      }
    } else if (def.type != "STRING") {
      Fail(fmt::format("attribute {}: unknown type {}", name, def.type));
    }
    Expect(';');
    attribute_defs_[name] = std::move(def);
  }

  std::string AttributeValueText() {
    SkipSpace();
    if (Peek() == '"') return String();
    return std::string(NumberToken());
  }

  void AttributeDefault() {
    const std::string name = String();
    const std::string value = AttributeValueText();
    Expect(';');
    auto it = attribute_defs_.find(name);
    if (it == attribute_defs_.end())
      Fail(fmt::format("BA_DEF_DEF_ of undefined attribute {}", name));
    it->second.default_value = value;
  }

  void Attribute() {
    const std::string name = String();
    SkipSpace();
    if (Peek() == '"' || !IsIdentStart(Peek())) {  // network attribute
      (void)AttributeValueText();
      Expect(';');
      return;
    }
    const std::string_view kind = Ident();
    if (kind == "BO_") {
      const std::uint32_t raw = RawMessageId();
      std::string value = AttributeValueText();
      Expect(';');
      if (raw == kIndependentSignalsId) return;
      DbcMessage& m = RequireMessage(raw);
      if (name == "GenMsgCycleTime") m.cycle_time_ms = CycleTime(value);
      m.attributes[name] = std::move(value);
      return;
    }
    if (kind == "SG_") {
      const std::uint32_t raw = RawMessageId();
      const std::string sig(Ident());
      std::string value = AttributeValueText();
      Expect(';');
      if (raw != kIndependentSignalsId) RequireSignal(raw, sig).attributes[name] = std::move(value);
      return;
    }
    if (kind == "BU_" || kind == "EV_") {
      (void)Ident();
      (void)AttributeValueText();
      Expect(';');
      return;
    }
    Fail(fmt::format("BA_ {} on unknown object type '{}'", name, kind));
  }

  int CycleTime(const std::string& text) {
    double v = 0;
    const auto r = std::from_chars(text.data(), text.data() + text.size(), v);
    if (r.ec != std::errc() || r.ptr != text.data() + text.size() || !(v >= 0) || v > 3.6e6 ||
        v != std::floor(v)) {
      Fail(fmt::format("GenMsgCycleTime '{}' must be a whole number of ms >= 0", text));
    }
    return static_cast<int>(v);
  }

  void SignalValueType() {
    const std::uint32_t raw = RawMessageId();
    const std::string name(Ident());
    Accept(':');
    const std::int64_t type = Int();
    Expect(';');
    if (raw == kIndependentSignalsId) return;
    DbcSignal& sig = RequireSignal(raw, name);
    if (type == 0) {
      sig.value_type = DbcValueType::kInteger;
    } else if (type == 1 || type == 2) {
      const int want = type == 1 ? 32 : 64;
      if (sig.length != want) {
        Fail(fmt::format("signal {}: SIG_VALTYPE_ {} needs a {}-bit signal, it has {}", name, type,
                         want, sig.length));
      }
      sig.value_type = type == 1 ? DbcValueType::kFloat32 : DbcValueType::kFloat64;
    } else {
      Fail(fmt::format("signal {}: SIG_VALTYPE_ must be 0, 1 or 2", name));
    }
  }

  void Finish() {
    // GenMsgCycleTime default applies to messages without their own value.
    auto it = attribute_defs_.find("GenMsgCycleTime");
    const int default_cycle = it != attribute_defs_.end() && !it->second.default_value.empty()
                                  ? CycleTime(it->second.default_value)
                                  : 0;
    for (std::size_t i = 0; i < db_.messages_.size(); ++i) {
      DbcMessage& m = db_.messages_[i];
      if (!m.cycle_time_ms && default_cycle > 0) m.cycle_time_ms = default_cycle;
      ResolveAttributes("BO_", m.attributes);
      for (auto& sig : m.signals) ResolveAttributes("SG_", sig.attributes);
      CheckOverlaps(m, message_lines_[i]);
      const bool has_mux = m.multiplexer() != nullptr;
      for (const auto& sig : m.signals) {
        if (sig.multiplex_value && !has_mux) {
          FailAt(message_lines_[i], fmt::format("message {}: signal {} is multiplexed (m{}) but "
                                                "the message has no multiplexer switch (M)",
                                                m.name, sig.name, *sig.multiplex_value));
        }
        if (sig.is_multiplexer && sig.value_type != DbcValueType::kInteger) {
          FailAt(message_lines_[i],
                 fmt::format("message {}: multiplexer {} cannot be a float", m.name, sig.name));
        }
      }
    }
    db_.BuildIndex();
  }

  // Defaults for the attributes not given, enum values as their strings (tools write an ENUM
  // attribute's index; its meaning is the string: GenMsgSendType's order differs between tools).
  void ResolveAttributes(std::string_view object,
                         std::map<std::string, std::string, std::less<>>& values) const {
    for (const auto& [name, def] : attribute_defs_) {
      if (def.object != object) continue;
      auto it = values.find(name);
      if (it == values.end()) {
        if (def.default_value.empty()) continue;
        it = values.emplace(name, def.default_value).first;
      }
      if (def.type != "ENUM") continue;
      std::size_t index = 0;
      const std::string& v = it->second;
      const auto r = std::from_chars(v.data(), v.data() + v.size(), index);
      if (r.ec == std::errc() && r.ptr == v.data() + v.size() && index < def.enum_values.size()) {
        it->second = def.enum_values[index];
      }
    }
  }

  // The payload bits a signal occupies (Intel: LSB upwards; Motorola: from its MSB in sawtooth
  // numbering, down a byte then on to the next byte's bit 7).
  static std::bitset<512> SignalBits(const DbcSignal& sig) {
    std::bitset<512> bits;
    int b = sig.start_bit;
    for (int i = 0; i < sig.length && b >= 0 && b < 512; ++i) {
      bits.set(static_cast<std::size_t>(b));
      if (sig.little_endian) {
        ++b;
      } else {
        b = (b % 8 == 0) ? b + 15 : b - 1;
      }
    }
    return bits;
  }

  // Two signals that can be in one frame (not multiplexed apart) must not share a bit. Each
  // bit's owner is kept, so that a message with thousands of multiplexed signals is checked in
  // one pass rather than pair by pair.
  void CheckOverlaps(const DbcMessage& m, int line) const {
    auto report = [&](std::size_t a, std::size_t b) {
      if (b < a) std::swap(a, b);
      const DbcSignal& sa = m.signals[a];
      const DbcSignal& sb = m.signals[b];
      const std::bitset<512> common = SignalBits(sa) & SignalBits(sb);
      std::size_t first = 0;
      while (!common.test(first)) ++first;
      FailAt(line, fmt::format("message {}: signals {} and {} overlap (both use bit {}, "
                               "{} bits in common)",
                               m.name, sa.name, sb.name, first, common.count()));
    };
    constexpr std::size_t kNone = static_cast<std::size_t>(-1);
    // Signals in every frame (the switch included) first, then each multiplexer value's.
    std::vector<std::size_t> in_every_frame(512, kNone);
    std::map<int, std::vector<std::size_t>> by_value;
    for (std::size_t i = 0; i < m.signals.size(); ++i) {
      const DbcSignal& sig = m.signals[i];
      if (sig.multiplex_value) {
        by_value[*sig.multiplex_value].push_back(i);
        continue;
      }
      const std::bitset<512> bits = SignalBits(sig);
      for (std::size_t b = 0; b < 512; ++b) {
        if (!bits.test(b)) continue;
        if (in_every_frame[b] != kNone) report(in_every_frame[b], i);
        in_every_frame[b] = i;
      }
    }
    std::vector<std::size_t> in_this_value(512, kNone);
    for (const auto& [value, signals] : by_value) {
      std::fill(in_this_value.begin(), in_this_value.end(), kNone);
      for (const std::size_t i : signals) {
        const std::bitset<512> bits = SignalBits(m.signals[i]);
        for (std::size_t b = 0; b < 512; ++b) {
          if (!bits.test(b)) continue;
          if (in_every_frame[b] != kNone) report(in_every_frame[b], i);
          if (in_this_value[b] != kNone) report(in_this_value[b], i);
          in_this_value[b] = i;
        }
      }
    }
  }

  std::string_view s_;
  const std::string& source_;
  std::size_t pos_ = 0;
  std::size_t line_start_ = 0;
  int line_ = 1;
  int statement_line_ = 1;
  std::string last_ident_;
  int current_message_ = -1;
  bool skipping_message_ = false;
  std::vector<int> message_lines_;
  std::unordered_map<std::uint64_t, std::size_t> message_by_id_;
  std::set<std::string, std::less<>> message_names_;
  std::vector<std::unordered_map<std::string, std::size_t>> signal_by_name_;  // per message
  std::vector<bool> has_multiplexer_;                                         // per message
  std::map<std::string, AttributeDef> attribute_defs_;
  DbcDatabase db_;
};

const DbcSignal* DbcMessage::FindSignal(std::string_view signal_name) const {
  for (const auto& s : signals) {
    if (s.name == signal_name) return &s;
  }
  return nullptr;
}

const DbcSignal* DbcMessage::multiplexer() const {
  for (const auto& s : signals) {
    if (s.is_multiplexer) return &s;
  }
  return nullptr;
}

void DbcDatabase::BuildIndex() {
  by_id_.clear();
  by_name_.clear();
  for (std::size_t i = 0; i < messages_.size(); ++i) {
    const auto& m = messages_[i];
    by_id_[static_cast<std::uint64_t>(m.id) | (m.extended ? (1ULL << 32) : 0)] = i;
    by_name_[m.name] = i;
  }
}

DbcDatabase DbcDatabase::Parse(std::string_view text, const std::string& source_name) {
  return DbcParser(text, source_name).Run();
}

DbcDatabase DbcDatabase::LoadFile(const std::string& path) {
  return Parse(
      internal::ReadInputFile(path, "DBC", kMaxFileBytes, "the largest real ones are tens of MiB"),
      path);
}

const DbcMessage* DbcDatabase::FindMessage(std::uint32_t id, bool extended) const {
  const auto it = by_id_.find(static_cast<std::uint64_t>(id) | (extended ? (1ULL << 32) : 0));
  return it == by_id_.end() ? nullptr : &messages_[it->second];
}

const DbcMessage* DbcDatabase::FindMessage(std::string_view name) const {
  const auto it = by_name_.find(name);
  return it == by_name_.end() ? nullptr : &messages_[it->second];
}

}  // namespace wheelhil::bus
