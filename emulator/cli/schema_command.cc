#include "emulator/cli/schema_command.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <set>
#include <stdexcept>

#include <fmt/format.h>

#include "bus/install_paths.h"
#include "bus/yaml_fields.h"
#include "emulator/campaign/campaign_spec.h"
#include "emulator/platforms/platform.h"
#include "emulator/scenario/scenario.h"
#include "emulator/scoring/output_binding.h"
#include "firmware_stub/fw_config.h"

namespace wheelhil::emulator {
namespace {

namespace fs = std::filesystem;
using bus::yaml::FieldRecorder;
using nlohmann::json;

// One position in a file: what the loader checked there.
struct Node {
  bool keys_checked = false;   // a mapping with a fixed set of keys
  std::set<std::string> keys;  // their union over every check
  bool open_map = false;       // a mapping of the user's names
  std::set<FieldRecorder::Kind> kinds;
  std::optional<double> min, max;  // the loosest range checked
  bool unbounded = false;          // read once without a range
  std::map<std::string, std::unique_ptr<Node>> children;
  std::unique_ptr<Node> items;  // a list's entries
  // A mapping whose keys depend on its `type:` (or `kind:`): the keys allowed with each value.
  std::string selector;
  std::map<std::string, std::set<std::string>> variants;
  bool mixed = false;  // entries chosen by different keys: only their union is described

  Node& Child(const std::string& key) {
    auto& c = children[key];
    if (!c) c = std::make_unique<Node>();
    return *c;
  }
  Node& Items() {
    if (!items) items = std::make_unique<Node>();
    return *items;
  }
};

// "a.b[2].c" -> {"a", "b", "[]", "c"}. Keys holding dots (a wheel pattern) stay whole only
// under open maps, where nothing below them is described anyway.
std::vector<std::string> Steps(std::string_view field) {
  std::vector<std::string> out;
  std::string cur;
  for (std::size_t i = 0; i < field.size(); ++i) {
    const char c = field[i];
    if (c == '.') {
      if (!cur.empty()) out.push_back(cur);
      cur.clear();
    } else if (c == '[') {
      if (!cur.empty()) out.push_back(cur);
      cur.clear();
      const std::size_t close = field.find(']', i);
      if (close == std::string_view::npos) break;
      out.push_back("[]");
      i = close;
    } else {
      cur += c;
    }
  }
  if (!cur.empty()) out.push_back(cur);
  return out;
}

class Recorder : public FieldRecorder {
 public:
  Recorder(std::string file, std::string root) : file_(std::move(file)), root_(std::move(root)) {}

  // Held per mapping (list indices kept) until Finish: its `type:` may be read after its keys.
  void Keys(const std::string& file, std::string_view field,
            const std::set<std::string>& allowed) override {
    Node* n = At(file, field);
    if (n == nullptr) return;
    Pending& p = pending_[std::string(field)];
    p.node = n;
    p.keys.insert(allowed.begin(), allowed.end());
  }
  void OpenMap(const std::string& file, std::string_view field) override {
    if (Node* n = At(file, field)) n->open_map = true;
  }
  void Value(const std::string& file, std::string_view field, Kind kind, std::optional<double> min,
             std::optional<double> max, std::string_view text) override {
    Node* n = At(file, field);
    if (n == nullptr) return;
    for (const std::string_view s : {std::string_view(".type"), std::string_view(".kind")}) {
      if (kind == Kind::kString && field.size() > s.size() && field.ends_with(s)) {
        Pending& p = pending_[std::string(field.substr(0, field.size() - s.size()))];
        if (p.selector == "type") continue;  // a fault's `type:` chooses, its `kind:` does not
        p.selector = std::string(s.substr(1));
        p.value = std::string(text);
      }
    }
    n->kinds.insert(kind);
    if (!min || !max) {
      n->unbounded = true;
    } else {
      n->min = n->min ? std::min(*n->min, *min) : *min;
      n->max = n->max ? std::max(*n->max, *max) : *max;
    }
  }
  // The mappings seen, each with its keys: under its type's value where a type chose them.
  void Finish() {
    for (auto& [field, p] : pending_) {
      if (p.node == nullptr) continue;
      p.node->keys.insert(p.keys.begin(), p.keys.end());
      if (!p.selector.empty() && p.keys.count(p.selector) != 0) {
        if (!p.node->selector.empty() && p.node->selector != p.selector) p.node->mixed = true;
        p.node->selector = p.selector;
        p.node->variants[p.value].insert(p.keys.begin(), p.keys.end());
      } else {
        p.node->keys_checked = true;
      }
    }
    pending_.clear();
  }

  Node& root() { return root_node_; }

 private:
  struct Pending {
    Node* node = nullptr;
    std::set<std::string> keys;
    std::string selector, value;
  };
  std::map<std::string, Pending> pending_;

  // The node at `field` of the file being described; nullptr for another file.
  Node* At(const std::string& file, std::string_view field) {
    if (fs::path(file).lexically_normal() != fs::path(file_).lexically_normal()) return nullptr;
    std::vector<std::string> steps = Steps(field);
    if (!root_.empty()) {
      if (steps.empty() || steps.front() != root_) return nullptr;
      steps.erase(steps.begin());
    }
    Node* n = &root_node_;
    for (const std::string& s : steps) n = s == "[]" ? &n->Items() : &n->Child(s);
    return n;
  }

  std::string file_;
  std::string root_;
  Node root_node_;
};

// Merges `b` into `a` (the same position seen in several files).
void Merge(Node& a, Node& b) {
  a.keys_checked = a.keys_checked || b.keys_checked;
  a.keys.insert(b.keys.begin(), b.keys.end());
  a.open_map = a.open_map || b.open_map;
  a.kinds.insert(b.kinds.begin(), b.kinds.end());
  a.unbounded = a.unbounded || b.unbounded;
  if (b.min) a.min = a.min ? std::min(*a.min, *b.min) : *b.min;
  if (b.max) a.max = a.max ? std::max(*a.max, *b.max) : *b.max;
  a.mixed = a.mixed || b.mixed ||
            (!a.selector.empty() && !b.selector.empty() && a.selector != b.selector);
  if (a.selector.empty()) a.selector = b.selector;
  for (const auto& [v, keys] : b.variants) a.variants[v].insert(keys.begin(), keys.end());
  for (auto& [k, c] : b.children) Merge(a.Child(k), *c);
  if (b.items) Merge(a.Items(), *b.items);
}

// The unit a wheelhil key names by its suffix.
std::string UnitOf(const std::string& key) {
  static const std::vector<std::pair<std::string, std::string>> kSuffixes = {
      {"_m_s2", "m/s^2"},
      {"_m_s", "m/s"},
      {"_rad_s2", "rad/s^2"},
      {"_rad_s", "rad/s"},
      {"_kg_m2", "kg*m^2"},
      {"_n_s_m", "N*s/m"},
      {"_n_m", "N/m"},
      {"_nm_s_rad", "N*m*s/rad"},
      {"_nm_rad", "N*m/rad"},
      {"_nm_a", "N*m/A"},
      {"_nm_s", "N*m*s"},
      {"_nm", "N*m"},
      {"_kg", "kg"},
      {"_deg", "deg"},
      {"_rad", "rad"},
      {"_hz", "Hz"},
      {"_bps", "bit/s"},
      {"_ms", "ms"},
      {"_s", "s"},
      {"_m", "m"},
      {"_a", "A"},
      {"_v", "V"},
      {"_ohm", "ohm"}};
  for (const auto& [suffix, unit] : kSuffixes) {
    if (key.size() > suffix.size() && key.ends_with(suffix)) return unit;
  }
  return {};
}

// Descriptions of fields by dotted path (list indices dropped): the docs' field tables.
using Descriptions = std::map<std::string, std::string>;

// The `| key | meaning |` tables of docs/scenarios.md's "Fields" section: each row's first
// backticked name (up to its first ':', ' ', '(' or '['), under its "### `section`" heading.
Descriptions ReadFieldTables(const fs::path& doc) {
  Descriptions out;
  std::ifstream in(doc);
  std::string line, section;
  bool in_fields = false, key_table = false;
  auto strip = [](std::string s) {
    s.erase(std::remove(s.begin(), s.end(), '`'), s.end());
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.erase(0, 1);
    return s;
  };
  while (std::getline(in, line)) {
    if (line.rfind("## ", 0) == 0) in_fields = line == "## Fields";
    if (!in_fields) continue;
    if (line.rfind("### ", 0) == 0) {
      const std::size_t a = line.find('`');
      const std::size_t b = a == std::string::npos ? a : line.find('`', a + 1);
      section = b == std::string::npos ? "" : line.substr(a + 1, b - a - 1);
      key_table = false;
      continue;
    }
    if (line.rfind("| key |", 0) == 0) {
      key_table = true;
      continue;
    }
    if (line.rfind("|", 0) != 0) {
      key_table = false;
      continue;
    }
    if (!key_table || line.rfind("|---", 0) == 0) continue;
    const std::size_t a = line.find('`');
    const std::size_t bar = line.find('|', 1);
    if (a == std::string::npos || bar == std::string::npos || a > bar) continue;
    const std::size_t end = line.find_first_of(":`([ ", a + 1);
    const std::string key = line.substr(a + 1, end - a - 1);
    std::string meaning = line.substr(bar + 1);
    if (!meaning.empty() && meaning.back() == '|') meaning.pop_back();
    if (key.empty()) continue;
    out[section.empty() ? key : section + "." + key] = strip(meaning);
  }
  return out;
}

json Emit(const Node& n, const std::string& key, const std::string& path,
          const Descriptions& docs) {
  json out = json::object();
  const std::string unit = UnitOf(key);
  auto child_path = [&](const std::string& k) { return path.empty() ? k : path + "." + k; };
  std::vector<json> alternatives;
  auto property = [&](const std::string& k) {
    const auto c = n.children.find(k);
    json schema = c == n.children.end() ? json::object() : Emit(*c->second, k, child_path(k), docs);
    if (c == n.children.end()) {
      if (const auto d = docs.find(child_path(k)); d != docs.end())
        schema["description"] = d->second;
    }
    return schema;
  };
  // Keys chosen by a type: one object per type value seen, its type pinned, and an open one for
  // the values no shipped file has (the loader knows them; the schema does not refuse them).
  std::set<std::set<std::string>> distinct;
  for (const auto& [v, keys] : n.variants) distinct.insert(keys);
  const bool by_type = !n.keys_checked && !n.mixed && distinct.size() > 1;
  if (by_type) {
    json variants = json::array();
    json seen = json::array();
    for (const auto& [v, keys] : n.variants) {
      json props = json::object();
      for (const std::string& k : keys) props[k] = property(k);
      props[n.selector]["const"] = v;
      variants.push_back({{"type", "object"},
                          {"properties", props},
                          {"required", json::array({n.selector})},
                          {"additionalProperties", false}});
      seen.push_back(v);
    }
    variants.push_back(
        {{"type", "object"}, {"properties", {{n.selector, {{"not", {{"enum", seen}}}}}}}});
    alternatives.push_back({{"anyOf", variants}});
  }
  if (!by_type && (n.keys_checked || !n.variants.empty())) {
    json props = json::object();
    for (const std::string& k : n.keys) props[k] = property(k);
    alternatives.push_back(
        {{"type", "object"}, {"properties", props}, {"additionalProperties", false}});
  } else if (distinct.empty() && (n.open_map || !n.children.empty())) {
    json o = {{"type", "object"}};
    if (!n.children.empty() && !n.open_map) {
      json props = json::object();
      for (const auto& [k, c] : n.children) props[k] = Emit(*c, k, child_path(k), docs);
      o["properties"] = props;
    }
    alternatives.push_back(o);
  }
  if (n.items) {
    alternatives.push_back(
        {{"type", "array"}, {"items", Emit(*n.items, key, path, Descriptions{})}});
  }
  if (!n.kinds.empty()) {
    json scalar = json::object();
    const bool number = n.kinds.count(FieldRecorder::Kind::kNumber) != 0;
    const bool integer = n.kinds.count(FieldRecorder::Kind::kInteger) != 0;
    const bool boolean = n.kinds.count(FieldRecorder::Kind::kBool) != 0;
    const bool string = n.kinds.count(FieldRecorder::Kind::kString) != 0;
    json types = json::array();
    // A YAML integer such as 0x174 arrives as an integer; a number may be written as one.
    if (number) types.push_back("number");
    if (integer && !number) types.push_back("integer");
    if (boolean) types.push_back("boolean");
    if (string) types.push_back("string");
    scalar["type"] = types.size() == 1 ? types[0] : types;
    if ((number || integer) && !n.unbounded && n.min && n.max && !string && !boolean) {
      if (std::isfinite(*n.min) && std::abs(*n.min) < 1e15) scalar["minimum"] = *n.min;
      if (std::isfinite(*n.max) && std::abs(*n.max) < 1e15) scalar["maximum"] = *n.max;
    }
    alternatives.push_back(scalar);
  }
  if (alternatives.size() == 1) {
    out = alternatives[0];
  } else if (alternatives.size() > 1) {
    out["anyOf"] = alternatives;
  }
  std::string description;
  if (const auto d = docs.find(path); d != docs.end()) description = d->second;
  if (!unit.empty()) description += (description.empty() ? "" : " ") + ("(unit: " + unit + ")");
  if (!description.empty()) out["description"] = description;
  return out;
}

// Loads `file` as `kind` (the loader's own checks; errors are the loader's).
void Load(const std::string& kind, const std::string& file) {
  if (kind == "scenario") {
    (void)scenario::LoadScenarioFile(file);
  } else if (kind == "platform") {
    (void)platforms::LoadPlatformFile(file);
  } else if (kind == "campaign") {
    (void)campaign::LoadCampaignFile(file);
  } else if (kind == "outputs") {
    const bus::yaml::FieldReader r("(schema)");
    YAML::Node n(file);
    (void)scoring::ReadOutputs(r, n, "outputs", ".");
  } else if (kind == "firmware-config") {
    (void)fw::LoadFwConfig(file);
  }
}

// Which dotted field of the file is its root (an outputs file reads as `outputs`).
std::string RootField(const std::string& kind) { return kind == "outputs" ? "outputs" : ""; }

const std::map<std::string, std::string>& Titles() {
  static const std::map<std::string, std::string> kTitles = {
      {"scenario", "wheelhil scenario (docs/scenarios.md)"},
      {"platform", "wheelhil platform (docs/physics.md, \"Platform files\")"},
      {"campaign", "wheelhil campaign (docs/campaigns.md)"},
      {"outputs", "wheelhil output binding: the firmware's frames (docs/own-hardware.md)"},
      {"firmware-config", "wheelhil-fw configuration (docs/firmware.md)"}};
  return kTitles;
}

}  // namespace

const std::vector<std::string>& SchemaKinds() {
  static const std::vector<std::string> kKinds = {"scenario", "platform", "campaign", "outputs",
                                                  "firmware-config"};
  return kKinds;
}

nlohmann::json FileSchema(const std::string& kind, const std::vector<std::string>& examples) {
  if (Titles().count(kind) == 0) {
    throw std::invalid_argument(
        fmt::format("schema: '{}' is not one of scenario, platform, "
                    "campaign, outputs, firmware-config",
                    kind));
  }
  Node all;
  for (const std::string& file : examples) {
    const std::string path = fs::absolute(file).lexically_normal().string();
    Recorder recorder(path, RootField(kind));
    FieldRecorder* previous = bus::yaml::RecordFieldsOnThisThread(&recorder);
    try {
      Load(kind, path);
    } catch (...) {
      bus::yaml::RecordFieldsOnThisThread(previous);
      throw;
    }
    bus::yaml::RecordFieldsOnThisThread(previous);
    recorder.Finish();
    Merge(all, recorder.root());
  }
  // The field tables of the docs where they are: the source tree's docs/, the installed ones.
  Descriptions docs;
  if (kind == "scenario") {
    const fs::path root = bus::FindShippedDataRoot(bus::RunningExecutableDir());
    for (const fs::path& doc :
         {root / "docs" / "scenarios.md", root / ".." / "doc" / "wheelhil" / "scenarios.md"}) {
      std::error_code ec;
      if (fs::is_regular_file(doc, ec)) {
        docs = ReadFieldTables(doc);
        break;
      }
    }
  }
  json schema = Emit(all, "", "", docs);
  schema["$schema"] = "https://json-schema.org/draft/2020-12/schema";
  schema["$id"] = fmt::format("https://wheelhil.invalid/schemas/{}.schema.json", kind);
  schema["title"] = Titles().at(kind);
  return schema;
}

std::vector<std::string> ShippedExamples(const std::string& kind) {
  const std::string root = bus::FindShippedDataRoot(bus::RunningExecutableDir());
  if (root.empty()) {
    throw std::invalid_argument("schema: the shipped scenarios are not next to this program");
  }
  const fs::path dir = fs::path(root) / "scenarios";
  std::vector<std::string> out;
  auto yaml_in = [&](const fs::path& d) {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(d, ec)) {
      if (e.is_regular_file() && e.path().extension() == ".yaml") out.push_back(e.path().string());
    }
  };
  if (kind == "scenario") {
    yaml_in(dir);
    for (const char* sub : {"smoke", "own_hardware", "urdf"}) yaml_in(dir / sub);
  } else if (kind == "platform") {
    yaml_in(dir / "platforms");
  } else if (kind == "campaign") {
    yaml_in(dir / "campaigns");
  } else if (kind == "outputs") {
    yaml_in(dir / "outputs");
  } else if (kind == "firmware-config") {
    yaml_in(dir / "firmware");
  }
  std::sort(out.begin(), out.end());
  return out;
}

SchemaCommand::SchemaCommand(CLI::App& app) {
  schema_ = app.add_subcommand(
      "schema", "Print the JSON Schema of a kind of file, for your editor (docs/schemas.md)");
  schema_->add_option("KIND", kind_, "scenario, platform, campaign, outputs or firmware-config");
  schema_->add_option("--out-dir", out_dir_,
                      "Write every kind's schema into this directory as KIND.schema.json");
}

std::optional<int> SchemaCommand::Run() {
  if (!schema_->parsed()) return std::nullopt;
  if (!out_dir_.empty()) {
    fs::create_directories(out_dir_);
    for (const std::string& kind : SchemaKinds()) {
      const fs::path file = fs::path(out_dir_) / (kind + ".schema.json");
      std::ofstream(file) << FileSchema(kind, ShippedExamples(kind)).dump(2) << "\n";
    }
    return 0;
  }
  if (kind_.empty()) {
    throw std::invalid_argument(
        "schema: name a kind (scenario, platform, campaign, outputs, firmware-config) or give "
        "--out-dir");
  }
  fmt::print("{}\n", FileSchema(kind_, ShippedExamples(kind_)).dump(2));
  return 0;
}

}  // namespace wheelhil::emulator
