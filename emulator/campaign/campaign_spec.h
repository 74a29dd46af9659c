#pragma once
/// Campaign files (docs/campaigns.md) and their expansion into a deterministic run list.
///
/// A campaign names a base scenario, the parameters to vary (each addressed by a dotted path
/// into the scenario such as `terrain.friction` or `faults[0].probability`, and given as a list,
/// a range with steps or a random distribution), how to sample them (grid, seeded random or
/// Latin hypercube), how often to repeat each point with a different seed, and pass criteria per
/// run and for the campaign as a whole. Expansion is a pure function of the file: the same file
/// gives the same runs, keys and seeds on every machine (own RNG arithmetic, no std::
/// distributions), which is what makes resume, sharding and merging work.
/// Thread-compatible value types.

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace wheelhil::emulator::campaign {

/// One varied parameter. Values are JSON scalars (numbers, strings, bools) so that a list may
/// also vary e.g. a terrain name, or, in a `values:` list, arrays of scalars for a path that
/// holds a list in the base (e.g. `sensors.accel4.bias_m_s2`).
struct ParameterSpec {
  enum class Kind { kList, kRange, kUniform, kNormal, kLogUniform };
  std::string path;  ///< dotted path into the base scenario; linked paths joined by " + "
  /// Where the value goes: `path: a.b` -> {a.b}; `path: [a.b, c.d]` (linked) sets every path
  /// to the same value (e.g. one threshold for the x and y axes).
  std::vector<std::string> paths;
  Kind kind = Kind::kList;
  std::vector<nlohmann::json> values;  ///< kList
  double from = 0, to = 0;             ///< kRange (inclusive), kUniform/kLogUniform bounds
  int steps = 0;                       ///< kRange: number of grid values (>= 2, or 1 = from)
  double mean = 0, stddev = 0;         ///< kNormal
  int line = 0;                        ///< line of this entry in the campaign file
  int column = 0;                      ///< and its column
  /// Grid values (kList: the list, kRange: `steps` values from..to). Empty for distributions.
  std::vector<nlohmann::json> GridValues() const;
  /// Maps u in [0, 1) to a value (inverse CDF; lists pick floor(u * size)).
  nlohmann::json FromUnit(double u) const;
};

/// A run-level condition on one metric of report.json (flattened name, see run_report.h).
struct MetricBound {
  std::string metric;
  std::optional<double> max;  ///< metric <= max
  std::optional<double> min;  ///< metric >= min
  int line = 0, column = 0;
  /// True when `value` satisfies the bound (a missing metric never does).
  bool Holds(std::optional<double> value) const;
  std::string Describe() const;  ///< e.g. "pose.final_error_m <= 0.1"
};

/// Campaign-wide condition: at least `fraction` of the runs satisfy `bound`, or, without a
/// bound, at least `fraction` of the runs passed.
struct CampaignCriterion {
  std::optional<MetricBound> bound;
  double fraction = 1.0;
  int line = 0, column = 0;
  std::string Describe() const;
};

/// A fixed value written into every run's scenario before the varied parameters (`set:`), e.g.
/// to cut a run short or to add a key the base leaves at its default. Unlike a parameter path,
/// its last segment may be missing from the base (its parent must exist).
struct Override {
  std::string path;
  nlohmann::json value;
  int line = 0, column = 0;
};

struct CampaignSpec {
  enum class Sampling { kGrid, kRandom, kLatinHypercube };
  /// Most runs a campaign may expand to (points x repeats), checked when it is loaded.
  static constexpr std::size_t kMaxRuns = 1'000'000;
  std::string file;                     ///< campaign file path as given
  std::string name;                     ///< `campaign:` (default: file stem)
  std::filesystem::path base_scenario;  ///< absolute
  /// The base scenario's text as read when the campaign was loaded, the text its fingerprint
  /// covers: every run is written from it, so a base edited while the campaign runs changes no
  /// run. Unset (a spec built in code): the file is read for each run.
  std::optional<std::string> base_text;
  std::vector<Override> overrides;      ///< `set:`, applied first
  std::vector<ParameterSpec> parameters;
  Sampling sampling = Sampling::kGrid;
  int runs = 0;                      ///< random/LHS: number of points (grid: product of the grids)
  std::uint64_t seed = 1;            ///< sampling seed and root of the run seeds
  int repeats = 1;                   ///< runs per point, each with its own seed
  bool require_verdict_pass = true;  ///< a run passes only if report.json's verdict is pass
  std::vector<MetricBound> run_criteria;
  std::vector<CampaignCriterion> campaign_criteria;
  std::string rank_metric;  ///< worst runs = largest value of this (default: first criterion)
  double timeout_s = 600;   ///< per run; a run over time is killed and counted as failed
  std::string fingerprint;  ///< hash of everything that decides the run list (hex)
};

/// Loads and validates a campaign file. Throws std::invalid_argument
/// "file:line:col: field: problem".
CampaignSpec LoadCampaignFile(const std::filesystem::path& file);
/// Same from text; `file` names it in errors and relative paths resolve against its directory.
CampaignSpec ParseCampaign(const std::string& yaml_text, const std::string& file);

/// One run of the expanded list.
struct RunSpec {
  int index = 0;   ///< position in the full run list (0-based)
  int point = 0;   ///< sample point
  int repeat = 0;  ///< 0..repeats-1
  std::uint64_t seed = 0;
  std::vector<nlohmann::json> values;  ///< one per CampaignSpec::parameters
  std::string key;                     ///< stable identity, e.g. "p00012-r1-3f9a0c1d2e4b5a67"
  nlohmann::json ParamsJson(const CampaignSpec& spec) const;  ///< {"path": value, ...}
};

/// How many runs `spec` expands to (points x repeats), kMaxRuns + 1 for anything more.
std::size_t RunCount(const CampaignSpec& spec);

/// The full run list, in a deterministic order (points in sampling order, repeats inner).
std::vector<RunSpec> ExpandRuns(const CampaignSpec& spec);

/// `--shard K/N`: K in [0, N). Parses "K/N"; throws std::invalid_argument when malformed.
struct Shard {
  int k = 0;
  int n = 1;
  static Shard Parse(const std::string& text);
  bool Contains(const RunSpec& run) const { return run.index % n == k; }
};

/// Runs of `runs` that belong to `shard` (round-robin by index, so shards stay balanced).
std::vector<RunSpec> SelectShard(const std::vector<RunSpec>& runs, const Shard& shard);

/// Deterministic 64-bit helpers (exposed for tests).
std::uint64_t SplitMix64(std::uint64_t x);
std::uint64_t Fnv1a64(const std::string& text);
/// Inverse standard normal CDF (Acklam's rational approximation, |error| < 1.2e-9).
double InverseNormalCdf(double p);

}  // namespace wheelhil::emulator::campaign
