#pragma once
/// Writes the scenario file of one campaign run: the base scenario with the varied parameters
/// set at their dotted paths. Relative file references of the base (any string value naming an
/// existing file or folder relative to the base's directory) become absolute, so the generated
/// file works from the run directory; so do those among the `set:` and parameter values
/// (relative to the campaign file's directory). A list value (JSON array) replaces a list of
/// the base, a scalar a scalar. Thread-compatible.

#include <yaml-cpp/yaml.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>

namespace wheelhil::emulator::campaign {

struct CampaignSpec;
struct RunSpec;

/// Splits "faults[0].probability" into {"faults", 0, "probability"}-style segments and sets the
/// value there. The path must already exist in `root` (a campaign varies what the base defines):
/// otherwise throws std::invalid_argument "<where>: <path>: <problem>", where `where` is e.g.
/// "campaign.yaml:12:5: path" and the problem names the first missing segment.
/// With `create_leaf`, a missing last mapping key is added (its parent must exist).
void SetAtPath(YAML::Node root, const std::string& path, const nlohmann::json& value,
               const std::string& where, bool create_leaf = false);

/// Throws like SetAtPath when any `set:` or parameter path of `spec` is missing from the base
/// scenario; call once before running so that errors come before any run starts.
void CheckParameterPaths(const CampaignSpec& spec);

/// Writes `out_file` (YAML) for `run`. Throws std::invalid_argument / std::runtime_error.
void WriteRunScenario(const CampaignSpec& spec, const RunSpec& run,
                      const std::filesystem::path& out_file);

}  // namespace wheelhil::emulator::campaign
