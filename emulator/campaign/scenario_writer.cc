#include "emulator/campaign/scenario_writer.h"

#include <fmt/format.h>

#include <cctype>
#include <fstream>
#include <stdexcept>
#include <variant>
#include <vector>

#include "bus/yaml_fields.h"
#include "emulator/campaign/campaign_spec.h"

namespace wheelhil::emulator::campaign {
namespace {

namespace fs = std::filesystem;
using Segment = std::variant<std::string, std::size_t>;

std::vector<Segment> SplitPath(const std::string& path, const std::string& where) {
  std::vector<Segment> out;
  std::size_t i = 0;
  auto fail = [&](const std::string& problem) {
    throw std::invalid_argument(fmt::format("{}: {}: {}", where, path, problem));
  };
  while (i < path.size()) {
    if (path[i] == '[') {
      const auto close = path.find(']', i);
      if (close == std::string::npos) fail("unclosed '['");
      const std::string num = path.substr(i + 1, close - i - 1);
      if (num.empty() || num.find_first_not_of("0123456789") != std::string::npos) {
        fail(fmt::format("index '{}' is not a number", num));
      }
      if (num.size() > 6) fail(fmt::format("index '{}' is past any list of a scenario", num));
      out.emplace_back(static_cast<std::size_t>(std::stoul(num)));
      i = close + 1;
      if (i < path.size() && path[i] == '.') ++i;
    } else {
      std::size_t end = i;
      while (end < path.size() && path[end] != '.' && path[end] != '[') ++end;
      if (end == i) fail("empty segment");
      out.emplace_back(path.substr(i, end - i));
      i = end;
      if (i < path.size() && path[i] == '.') {
        ++i;
        if (i == path.size()) fail("ends with '.'");
      }
    }
  }
  if (out.empty()) fail("empty path");
  return out;
}

YAML::Node ToYaml(const nlohmann::json& v) {
  if (v.is_boolean()) return YAML::Node(v.get<bool>());
  if (v.is_number_integer()) return YAML::Node(v.get<long long>());
  if (v.is_number()) {
    // Shortest text that reads back as the same double.
    const double d = v.get<double>();
    return YAML::Node(fmt::format("{}", d));
  }
  if (v.is_string()) return YAML::Node(v.get<std::string>());
  if (v.is_array()) {
    YAML::Node seq(YAML::NodeType::Sequence);
    seq.SetStyle(YAML::EmitterStyle::Flow);
    for (const auto& e : v) seq.push_back(ToYaml(e));
    return seq;
  }
  return YAML::Node(v.dump());
}

// A string value naming an existing file or folder relative to `dir` (the campaign file's
// folder) becomes absolute, like the base scenario's own references; lists entry by entry.
nlohmann::json ResolveFiles(const nlohmann::json& v, const fs::path& dir) {
  if (v.is_array()) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& e : v) out.push_back(ResolveFiles(e, dir));
    return out;
  }
  if (!v.is_string()) return v;
  const auto& s = v.get_ref<const std::string&>();
  if (s.empty() || s.size() > 4096 || s.front() == '/' ||
      s.find_first_of("/.") == std::string::npos || s.find('\n') != std::string::npos) {
    return v;
  }
  std::error_code ec;
  const fs::path candidate = (dir / s).lexically_normal();
  return fs::exists(candidate, ec) ? nlohmann::json(candidate.string()) : v;
}

// Recursive so that every step works on a fresh YAML::Node handle (assigning one Node to
// another rebinds the tree in yaml-cpp).
void SetRec(YAML::Node node, const std::vector<Segment>& segs, std::size_t i,
            const nlohmann::json& value, const std::string& path, const std::string& where,
            std::string& prefix, bool create_leaf) {
  const Segment& seg = segs[i];
  const bool last = i + 1 == segs.size();
  if (const auto* key = std::get_if<std::string>(&seg)) {
    const std::string here = prefix.empty() ? *key : prefix + "." + *key;
    const bool create = create_leaf && last && node.IsMap();
    if (!create && (!node.IsMap() || !node[*key])) {
      throw std::invalid_argument(
          fmt::format("{}: {}: '{}' does not exist in the base scenario{}", where, path, here,
                      node.IsMap() ? "" : fmt::format(" ('{}' is not a mapping)", prefix)));
    }
    prefix = here;
    if (last) {
      const YAML::Node old = node[*key];
      // A scalar replaces a scalar; a list value replaces a list (or fills a new/null key).
      const bool fits =
          !old || old.IsNull() || (value.is_array() ? old.IsSequence() : old.IsScalar());
      if (!fits) {
        throw std::invalid_argument(fmt::format("{}: {}: '{}' is not a {} in the base scenario",
                                                where, path, here,
                                                value.is_array() ? "list" : "scalar"));
      }
      node[*key] = ToYaml(value);
    } else {
      SetRec(node[*key], segs, i + 1, value, path, where, prefix, create_leaf);
    }
  } else {
    const std::size_t idx = std::get<std::size_t>(seg);
    const std::string here = fmt::format("{}[{}]", prefix, idx);
    if (!node.IsSequence() || idx >= node.size()) {
      throw std::invalid_argument(
          fmt::format("{}: {}: '{}' does not exist in the base scenario ({})", where, path, here,
                      node.IsSequence() ? fmt::format("'{}' has {} entries", prefix, node.size())
                                        : fmt::format("'{}' is not a list", prefix)));
    }
    prefix = here;
    if (last) {
      if (value.is_array() != node[idx].IsSequence()) {
        throw std::invalid_argument(fmt::format("{}: {}: '{}' is not a {} in the base scenario",
                                                where, path, here,
                                                value.is_array() ? "list" : "scalar"));
      }
      node[idx] = ToYaml(value);
    } else {
      SetRec(node[idx], segs, i + 1, value, path, where, prefix, create_leaf);
    }
  }
}

void AbsolutizeRelativePaths(YAML::Node node, const fs::path& base_dir) {
  if (node.IsMap()) {
    for (auto kv : node) AbsolutizeRelativePaths(kv.second, base_dir);
  } else if (node.IsSequence()) {
    for (std::size_t i = 0; i < node.size(); ++i) AbsolutizeRelativePaths(node[i], base_dir);
  } else if (node.IsScalar()) {
    const std::string& s = node.Scalar();
    if (s.empty() || s.size() > 4096 || s.front() == '/' ||
        s.find_first_of("/.") == std::string::npos || s.find('\n') != std::string::npos) {
      return;
    }
    std::error_code ec;
    const fs::path candidate = (base_dir / s).lexically_normal();
    if (fs::exists(candidate, ec)) node = candidate.string();
  }
}

YAML::Node LoadBase(const CampaignSpec& spec) {
  const bus::yaml::FieldReader base(spec.base_scenario.string());
  return base.Parse(spec.base_text ? *spec.base_text : base.ReadFile());
}

}  // namespace

void SetAtPath(YAML::Node root, const std::string& path, const nlohmann::json& value,
               const std::string& where, bool create_leaf) {
  const auto segs = SplitPath(path, where);
  std::string prefix;
  SetRec(root, segs, 0, value, path, where, prefix, create_leaf);
}

namespace {
fs::path CampaignDir(const CampaignSpec& spec) { return fs::absolute(spec.file).parent_path(); }

void ApplyOverrides(const CampaignSpec& spec, YAML::Node root) {
  for (const auto& o : spec.overrides) {
    SetAtPath(root, o.path, ResolveFiles(o.value, CampaignDir(spec)),
              fmt::format("{}:{}:{}: set", spec.file, o.line, o.column),
              /*create_leaf=*/true);
  }
}
}  // namespace

void CheckParameterPaths(const CampaignSpec& spec) {
  YAML::Node base = LoadBase(spec);
  ApplyOverrides(spec, base);
  for (const auto& p : spec.parameters) {
    for (const auto& path : p.paths) {
      SetAtPath(base, path,
                p.kind == ParameterSpec::Kind::kList ? p.values.front() : nlohmann::json(p.from),
                fmt::format("{}:{}:{}: path", spec.file, p.line, p.column));
    }
  }
}

void WriteRunScenario(const CampaignSpec& spec, const RunSpec& run, const fs::path& out_file) {
  YAML::Node root = LoadBase(spec);
  AbsolutizeRelativePaths(root, spec.base_scenario.parent_path());
  ApplyOverrides(spec, root);
  for (std::size_t i = 0; i < spec.parameters.size(); ++i) {
    for (const auto& path : spec.parameters[i].paths) {
      SetAtPath(root, path, ResolveFiles(run.values.at(i), CampaignDir(spec)),
                fmt::format("{}:{}:{}: path", spec.file, spec.parameters[i].line,
                            spec.parameters[i].column));
    }
  }
  YAML::Emitter out;
  out << root;
  std::ofstream f(out_file, std::ios::trunc);
  f << "# Generated by `wheelhil campaign` from " << spec.base_scenario.string() << "\n"
    << "# campaign " << spec.name << ", run " << run.key << ", seed " << run.seed << "\n"
    << out.c_str() << "\n";
  if (!f) throw std::runtime_error(fmt::format("cannot write {}", out_file.string()));
}

}  // namespace wheelhil::emulator::campaign
