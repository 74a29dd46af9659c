#include "bus/canopen_eds.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <stdexcept>
#include <unordered_map>

#include <fmt/format.h>

#include "bus/internal/input_file.h"

namespace wheelhil::bus {

namespace {

std::string_view Trim(std::string_view s) {
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front())) != 0) s.remove_prefix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back())) != 0) s.remove_suffix(1);
  return s;
}

std::string Lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

// An unsigned integer as CiA 306 writes it: decimal, 0x hexadecimal, 0-prefixed octal.
std::optional<std::uint64_t> ParseUnsigned(std::string_view s) {
  s = Trim(s);
  int base = 10;
  if (s.size() > 2 && s[0] == '0' && (s[1] == 'x' || s[1] == 'X')) {
    base = 16;
    s.remove_prefix(2);
  } else if (s.size() > 1 && s[0] == '0') {
    base = 8;
    s.remove_prefix(1);
  }
  std::uint64_t v = 0;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v, base);
  if (s.empty() || r.ec != std::errc() || r.ptr != s.data() + s.size()) return std::nullopt;
  return v;
}

// The value of an integer expression: 128 bits, so that no sum of 64-bit terms overflows
// before it is compared with its data type's range.
struct Evaluated {
  enum Status { kOk, kNotAnInteger, kBeyond64Bits } status = kNotAnInteger;
  __int128 value = 0;
};

// "$NODEID+0x180", "0x180+$NODEID", "-5", "12": terms joined by + or -.
Evaluated EvaluateValue(std::string_view text, int node_id) {
  std::string s;
  for (char c : text) {
    if (std::isspace(static_cast<unsigned char>(c)) == 0) s.push_back(c);
  }
  if (s.empty()) return {};
  // Any partial sum beyond this is out of every data type's range (and far from overflowing).
  constexpr __int128 kLimit = static_cast<__int128>(1) << 66;
  __int128 total = 0;
  std::size_t i = 0;
  int sign = 1;
  if (s[0] == '-' || s[0] == '+') {
    sign = s[0] == '-' ? -1 : 1;
    i = 1;
  }
  while (i <= s.size()) {
    std::size_t j = i;
    while (j < s.size() && s[j] != '+' && s[j] != '-') ++j;
    const std::string_view term(s.data() + i, j - i);
    __int128 v = 0;
    if (Lower(term) == "$nodeid") {
      v = node_id;
    } else if (const auto u = ParseUnsigned(term)) {
      v = static_cast<__int128>(*u);
    } else {
      return {};
    }
    total += sign * v;
    if (total > kLimit || total < -kLimit) return {Evaluated::kBeyond64Bits, 0};
    if (j == s.size()) break;
    sign = s[j] == '-' ? -1 : 1;
    i = j + 1;
  }
  return {Evaluated::kOk, total};
}

// The integer data types of CiA 301 (7.1.6) this reader knows: size in the object, range.
struct IntegerType {
  std::uint16_t code;
  std::string_view name;
  int bytes;
  int value_bits;  // BOOLEAN takes a byte and holds 0 or 1
  bool is_signed;
  __int128 min() const { return is_signed ? -(static_cast<__int128>(1) << (value_bits - 1)) : 0; }
  __int128 max() const {
    return (static_cast<__int128>(1) << (is_signed ? value_bits - 1 : value_bits)) - 1;
  }
};

constexpr IntegerType kIntegerTypes[] = {
    {0x0001, "BOOLEAN", 1, 1, false},     {0x0002, "INTEGER8", 1, 8, true},
    {0x0003, "INTEGER16", 2, 16, true},   {0x0004, "INTEGER32", 4, 32, true},
    {0x0005, "UNSIGNED8", 1, 8, false},   {0x0006, "UNSIGNED16", 2, 16, false},
    {0x0007, "UNSIGNED32", 4, 32, false}, {0x0010, "INTEGER24", 3, 24, true},
    {0x0015, "INTEGER64", 8, 64, true},   {0x0016, "UNSIGNED24", 3, 24, false},
    {0x001B, "UNSIGNED64", 8, 64, false},
};

const IntegerType* FindIntegerType(std::uint16_t data_type) {
  for (const IntegerType& t : kIntegerTypes) {
    if (t.code == data_type) return &t;
  }
  return nullptr;
}

std::string Decimal(__int128 v) {
  if (v == 0) return "0";
  const bool negative = v < 0;
  unsigned __int128 m =
      negative ? -static_cast<unsigned __int128>(v) : static_cast<unsigned __int128>(v);
  std::string digits;
  for (; m != 0; m /= 10) digits.insert(digits.begin(), static_cast<char>('0' + m % 10));
  return negative ? "-" + digits : digits;
}

// `e`'s value with this node id; when it is not an integer of its data type's range, what is
// wrong in `problem`, for "file:line: [1017] DefaultValue: <problem>".
__int128 CheckedValue(const EdsEntry& e, int node_id, bool with_node_id, std::string& problem) {
  const Evaluated v = EvaluateValue(e.default_value, node_id);
  if (v.status == Evaluated::kNotAnInteger) {
    problem =
        fmt::format("'{}' is not an integer (decimal, 0x.., or with $NODEID)", e.default_value);
    return 0;
  }
  const IntegerType* type = FindIntegerType(e.data_type);
  if (type == nullptr) return v.value;
  // Silently truncated to the object's size before: a heartbeat of 70000 ms became 4464.
  const std::string node = with_node_id ? fmt::format(" with node id {}", node_id) : std::string();
  if (v.status == Evaluated::kBeyond64Bits) {
    problem = fmt::format("'{}'{} is beyond 64 bits, outside {}'s range {}..{}", e.default_value,
                          node, type->name, Decimal(type->min()), Decimal(type->max()));
  } else if (v.value < type->min() || v.value > type->max()) {
    problem = fmt::format("'{}' is {}{}, outside {}'s range {}..{}", e.default_value,
                          Decimal(v.value), node, type->name, Decimal(type->min()),
                          Decimal(type->max()));
  }
  return v.value;
}

struct Section {
  std::string name;
  int line = 0;
  std::map<std::string, std::pair<std::string, int>, std::less<>> keys;  // lower-case key
  std::vector<std::pair<std::string, std::string>> as_written;
};

}  // namespace

int EdsFile::IntegerSize(std::uint16_t data_type) {
  const IntegerType* type = FindIntegerType(data_type);
  return type != nullptr ? type->bytes : 0;
}

EdsFile EdsFile::LoadFile(const std::string& path) {
  return Parse(
      internal::ReadInputFile(path, "EDS", kMaxFileBytes, "a device's EDS is at most a few MiB"),
      path);
}

EdsFile EdsFile::Parse(std::string_view text, const std::string& source_name) {
  // A leading byte-order mark (Windows tools write one) is not part of the first line.
  text = internal::SkipUtf8Bom(text);
  EdsFile eds;
  eds.source_ = source_name;
  std::vector<Section> sections;
  std::unordered_map<std::string, int> section_lines;  // a file may have 10^4 sections
  int line_no = 0;
  std::size_t pos = 0;
  auto fail = [&](int line, const std::string& problem) {
    throw std::invalid_argument(fmt::format("{}:{}: {}", source_name, line, problem));
  };
  while (pos <= text.size()) {
    const std::size_t end = std::min(text.find('\n', pos), text.size());
    std::string_view line = Trim(text.substr(pos, end - pos));
    pos = end + 1;
    ++line_no;
    if (line.empty() || line[0] == ';' || line[0] == '#') {
      if (end == text.size()) break;
      continue;
    }
    if (line.front() == '[') {
      if (line.back() != ']')
        fail(line_no, fmt::format("'{}': a section header ends with ']'", line));
      Section s;
      s.name = Lower(Trim(line.substr(1, line.size() - 2)));
      s.line = line_no;
      const auto [first, inserted] = section_lines.emplace(s.name, line_no);
      if (!inserted) {
        fail(line_no, fmt::format("[{}] appears twice (first at line {})", s.name, first->second));
      }
      sections.push_back(std::move(s));
    } else {
      const auto eq = line.find('=');
      if (eq == std::string_view::npos) fail(line_no, fmt::format("'{}' is not key=value", line));
      if (sections.empty()) fail(line_no, "a key before the first [section]");
      const std::string_view k = Trim(line.substr(0, eq));
      const std::string v(Trim(line.substr(eq + 1)));
      sections.back().keys[Lower(k)] = {v, line_no};
      sections.back().as_written.emplace_back(std::string(k), v);
    }
    if (end == text.size()) break;
  }
  auto key = [](const Section& s, std::string_view k) -> const std::pair<std::string, int>* {
    const auto it = s.keys.find(k);
    return it == s.keys.end() ? nullptr : &it->second;
  };
  auto number = [&](const Section& s, std::string_view k,
                    std::uint64_t max) -> std::optional<std::uint64_t> {
    const auto* v = key(s, k);
    if (v == nullptr || v->first.empty()) return std::nullopt;
    const auto n = ParseUnsigned(v->first);
    if (!n || *n > max) {
      fail(v->second,
           fmt::format("[{}] {}: '{}' is not a number up to {}", s.name, k, v->first, max));
    }
    return n;
  };
  std::map<std::string, const Section*> by_name;
  for (const Section& s : sections) by_name[s.name] = &s;
  for (const Section& s : sections) {
    if (s.name == "deviceinfo") {
      for (const auto& [k, v] : s.as_written) eds.info_[k] = v;
      continue;
    }
    if (s.name == "devicecomissioning" || s.name == "devicecommissioning") {
      if (const auto id = number(s, "nodeid", 127)) eds.node_id_ = static_cast<int>(*id);
      continue;
    }
    if (s.name == "dynamicchannels") fail(s.line, "[DynamicChannels] is not supported");
    if (s.name == "mandatoryobjects" || s.name == "optionalobjects" ||
        s.name == "manufacturerobjects") {
      const auto count = number(s, "supportedobjects", 0xFFFF).value_or(0);
      for (std::uint64_t i = 1; i <= count; ++i) {
        const auto idx = number(s, std::to_string(i), 0xFFFF);
        if (!idx) {
          fail(s.line, fmt::format("[{}] lists {} objects but has no entry {}", s.name, count, i));
        }
        const std::string want = Lower(fmt::format("{:04X}", *idx));
        if (!by_name.contains(want)) {
          fail(key(s, std::to_string(i))->second,
               fmt::format("[{}] {}: object 0x{:04X} has no section [{:04X}]", s.name, i, *idx,
                           *idx));
        }
      }
      continue;
    }
    // An object [XXXX] or a sub-object [XXXXsubN].
    const std::string& n = s.name;
    const auto sub_at = n.find("sub");
    const std::string index_text = n.substr(0, sub_at);
    const auto index = ParseUnsigned("0x" + index_text);
    if (index_text.size() != 4 || !index) continue;  // [FileInfo], [Comments], tool sections
    std::uint8_t sub = 0;
    if (sub_at != std::string::npos) {
      const auto sv = ParseUnsigned("0x" + n.substr(sub_at + 3));
      if (!sv || *sv > 0xFF) fail(s.line, fmt::format("[{}]: bad sub-index", n));
      sub = static_cast<std::uint8_t>(*sv);
    }
    if (key(s, "compactsubobj") != nullptr && number(s, "compactsubobj", 0xFF).value_or(0) != 0) {
      fail(key(s, "compactsubobj")->second,
           fmt::format("[{}] CompactSubObj is not supported: write the sub-objects out", n));
    }
    EdsEntry e;
    e.index = static_cast<std::uint16_t>(*index);
    e.sub = sub;
    e.line = s.line;
    if (const auto* v = key(s, "parametername")) e.name = v->first;
    e.object_type = static_cast<std::uint8_t>(number(s, "objecttype", 0xFF).value_or(0x7));
    if (sub_at == std::string::npos && (e.object_type == 0x8 || e.object_type == 0x9)) {
      continue;  // the ARRAY/RECORD itself: its values are in its sub-objects
    }
    if (e.object_type != 0x7 && sub_at == std::string::npos) continue;  // DOMAIN, DEFTYPE, ...
    const auto dt = number(s, "datatype", 0xFFFF);
    if (!dt) fail(s.line, fmt::format("[{}] DataType: is required", n));
    e.data_type = static_cast<std::uint16_t>(*dt);
    const auto* access = key(s, "accesstype");
    if (access == nullptr) fail(s.line, fmt::format("[{}] AccessType: is required", n));
    e.access = Lower(access->first);
    static const std::vector<std::string> kAccess{"ro", "wo", "rw", "rwr", "rww", "const"};
    if (std::find(kAccess.begin(), kAccess.end(), e.access) == kAccess.end()) {
      fail(access->second, fmt::format("[{}] AccessType: '{}' is not one of ro, wo, rw, rwr, "
                                       "rww, const",
                                       n, access->first));
    }
    e.value_line = s.line;
    if (const auto* v = key(s, "defaultvalue")) {
      e.default_value = v->first;
      e.value_line = v->second;
    }
    if (const auto* v = key(s, "parametervalue"); v != nullptr && !v->first.empty()) {
      e.default_value = v->first;
      e.value_key = "ParameterValue";
      e.value_line = v->second;
    }
    if (const auto* v = key(s, "pdomapping")) e.pdo_mapping = Trim(v->first) == "1";
    // An integer value must read as one now, and fit its type (with a node id of 1; the
    // node's own is checked when it is read): a typo is a load error.
    if (IntegerSize(e.data_type) > 0 && !e.default_value.empty()) {
      std::string why;
      CheckedValue(e, 1, false, why);
      if (!why.empty()) fail(e.value_line, fmt::format("[{}] {}: {}", n, e.value_key, why));
    }
    eds.entries_[{e.index, e.sub}] = std::move(e);
  }
  return eds;
}

std::uint8_t EdsFile::NodeIdFor(std::uint8_t configured, std::string_view device) const {
  if (node_id_) {
    if (configured == 0) configured = static_cast<std::uint8_t>(*node_id_);
    if (*node_id_ != configured) {
      throw std::invalid_argument(fmt::format("{}: the DCF is for node {}, the {} is node {}",
                                              source_, *node_id_, device, configured));
    }
  }
  if (configured == 0) {
    throw std::invalid_argument(source_ + ": an EDS names no node id: give node_id");
  }
  return configured;
}

const EdsEntry* EdsFile::Find(std::uint16_t index, std::uint8_t sub) const {
  const auto it = entries_.find({index, sub});
  return it == entries_.end() ? nullptr : &it->second;
}

std::uint64_t EdsFile::Integer(std::uint16_t index, std::uint8_t sub, int node_id) const {
  const EdsEntry* e = Find(index, sub);
  if (e == nullptr) {
    throw std::invalid_argument(
        fmt::format("{}: object 0x{:04X} sub {} is not in the file", source_, index, sub));
  }
  std::string why;
  const __int128 value = CheckedValue(*e, node_id, true, why);
  if (!why.empty()) {
    throw std::invalid_argument(fmt::format("{}:{}: [{:04X}{}] {}: {}", source_, e->value_line,
                                            index, sub != 0 ? fmt::format("sub{}", sub) : "",
                                            e->value_key, why));
  }
  // In range: a negative value of a signed type is its two's complement.
  return static_cast<std::uint64_t>(value);
}

}  // namespace wheelhil::bus
