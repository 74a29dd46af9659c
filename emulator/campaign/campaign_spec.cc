#include "emulator/campaign/campaign_spec.h"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>

#include "bus/yaml_fields.h"
#include "emulator/scoring/expectations.h"

namespace wheelhil::emulator::campaign {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Campaign fields. A campaign's integers may be written as 2 or 2.0; a plain scalar in a value
// list is a number or a boolean when it reads as one, a quoted one always a string.
class Loader : public bus::yaml::FieldReader {
 public:
  using FieldReader::FieldReader;

  int Line(const YAML::Node& node) const {
    return node.IsDefined() && !node.Mark().is_null() ? node.Mark().line + 1 : 0;
  }
  int Column(const YAML::Node& node) const {
    return node.IsDefined() && !node.Mark().is_null() ? node.Mark().column + 1 : 0;
  }

  // parent[key] as a finite number; required.
  double RequiredNumber(const YAML::Node& parent, const std::string& key,
                        const std::string& prefix) const {
    return Number(parent, key, prefix, -std::numeric_limits<double>::infinity(),
                  std::numeric_limits<double>::infinity());
  }
  int Integer(const YAML::Node& node, const std::string& field, int min_value) const {
    const double v = ToNumber(node, field);
    if (v != std::floor(v) || v < min_value || v > 1e9) {
      Fail(node, field, fmt::format("({}) must be an integer >= {}", node.Scalar(), min_value));
    }
    return static_cast<int>(v);
  }
  int Integer(const YAML::Node& parent, const std::string& key, const std::string& prefix,
              int min_value) const {
    const std::string field = Join(prefix, key);
    const YAML::Node n = Get(parent, key);
    if (!Present(n)) FailKey(parent, key, field, "is required");
    return Integer(n, field, min_value);
  }
  std::string NonEmpty(const YAML::Node& node, const std::string& field) const {
    const std::string s = ToString(node, field);
    if (s.empty()) Fail(node, field, "must be a non-empty string");
    return s;
  }
  std::string NonEmpty(const YAML::Node& parent, const std::string& key,
                       const std::string& field) const {
    const YAML::Node n = Get(parent, key);
    if (!Present(n)) FailKey(parent, key, field, "is required");
    return NonEmpty(n, field);
  }
  json Scalar(const YAML::Node& node, const std::string& field) const {
    if (!node.IsScalar()) Fail(node, field, "list entries must be scalars");
    const std::string& s = node.Scalar();
    if (node.Tag() != "!") {  // plain (unquoted) scalar: number or bool when it reads as one
      try {
        std::size_t used = 0;
        const double v = std::stod(s, &used);
        if (used == s.size() && std::isfinite(v)) return v;
      } catch (const std::exception&) {
      }
      if (s == "true") return true;
      if (s == "false") return false;
    }
    return s;
  }
  // A scalar, or a non-empty flow list of scalars (a list value, for a path that holds a list
  // in the base scenario, e.g. sensors.accel4.bias_m_s2).
  json ScalarOrList(const YAML::Node& node, const std::string& field) const {
    if (!node.IsSequence()) return Scalar(node, field);
    if (node.size() == 0) Fail(node, field, "a list value must not be empty");
    json out = json::array();
    for (const auto& e : node) {
      if (!e.IsScalar()) Fail(e, field, "a list value holds scalars only");
      out.push_back(Scalar(e, field));
    }
    return out;
  }

  MetricBound Bound(const YAML::Node& node, const std::string& field,
                    const std::set<std::string>& extra) const {
    std::set<std::string> allowed = {"metric", "max", "min"};
    allowed.insert(extra.begin(), extra.end());
    CheckKeys(node, field, allowed);
    MetricBound b;
    b.line = Line(node);
    b.column = Column(node);
    b.metric = NonEmpty(node, "metric", field + ".metric");
    if (node["max"]) b.max = ToNumber(node["max"], field + ".max");
    if (node["min"]) b.min = ToNumber(node["min"], field + ".min");
    if (!b.max && !b.min) Fail(node, field, "needs max or min");
    return b;
  }
};

std::string Hex64(std::uint64_t v) { return fmt::format("{:016x}", v); }

// Uniform double in [0, 1) from 53 random bits.
double Unit(std::uint64_t bits) { return static_cast<double>(bits >> 11) * 0x1.0p-53; }

class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  std::uint64_t Next() {
    state_ += 0x9e3779b97f4a7c15ULL;
    return SplitMix64(state_);
  }
  double Uniform() { return Unit(Next()); }
  // Uniform integer in [0, n).
  std::uint64_t Below(std::uint64_t n) { return static_cast<std::uint64_t>(Uniform() * n) % n; }

 private:
  std::uint64_t state_;
};

}  // namespace

std::uint64_t SplitMix64(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

std::uint64_t Fnv1a64(const std::string& text) {
  std::uint64_t h = 0xcbf29ce484222325ULL;
  for (unsigned char c : text) {
    h ^= c;
    h *= 0x100000001b3ULL;
  }
  return h;
}

double InverseNormalCdf(double p) {
  // Peter Acklam's algorithm with one Halley refinement step.
  static constexpr double a[] = {-3.969683028665376e+01, 2.209460984245205e+02,
                                 -2.759285104469687e+02, 1.383577518672690e+02,
                                 -3.066479806614716e+01, 2.506628277459239e+00};
  static constexpr double b[] = {-5.447609879822406e+01, 1.615858368580409e+02,
                                 -1.556989798598866e+02, 6.680131188771972e+01,
                                 -1.328068155288572e+01};
  static constexpr double c[] = {-7.784894002430293e-03, -3.223964580411365e-01,
                                 -2.400758277161838e+00, -2.549732539343734e+00,
                                 4.374664141464968e+00,  2.938163982698783e+00};
  static constexpr double d[] = {7.784695709041462e-03, 3.224671290700398e-01,
                                 2.445134137142996e+00, 3.754408661907416e+00};
  if (p <= 0) return -INFINITY;
  if (p >= 1) return INFINITY;
  constexpr double kLow = 0.02425;
  double x;
  if (p < kLow) {
    const double q = std::sqrt(-2 * std::log(p));
    x = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
        ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
  } else if (p <= 1 - kLow) {
    const double q = p - 0.5;
    const double r = q * q;
    x = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
        (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1);
  } else {
    const double q = std::sqrt(-2 * std::log(1 - p));
    x = -(((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
        ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1);
  }
  const double e = 0.5 * std::erfc(-x / std::sqrt(2.0)) - p;
  const double u = e * std::sqrt(2 * M_PI) * std::exp(x * x / 2);
  return x - u / (1 + x * u / 2);
}

std::vector<json> ParameterSpec::GridValues() const {
  switch (kind) {
    case Kind::kList:
      return values;
    case Kind::kRange: {
      std::vector<json> out;
      if (steps == 1) return {json(from)};
      for (int i = 0; i < steps; ++i) {
        // Exact end points; interior values rounded to 12 significant digits so that
        // 0.1 + 2 * 0.1 style noise never reaches the scenario file.
        double v = i == steps - 1 ? to : from + (to - from) * i / (steps - 1);
        v = std::stod(fmt::format("{:.12g}", v));
        out.emplace_back(v);
      }
      return out;
    }
    default:
      return {};
  }
}

json ParameterSpec::FromUnit(double u) const {
  u = std::clamp(u, 0.0, std::nextafter(1.0, 0.0));
  switch (kind) {
    case Kind::kList:
      return values[static_cast<std::size_t>(u * values.size())];
    case Kind::kRange:
    case Kind::kUniform:
      return from + (to - from) * u;
    case Kind::kLogUniform:
      return std::exp(std::log(from) + (std::log(to) - std::log(from)) * u);
    case Kind::kNormal:
      // Keep u away from 0 so the value stays finite.
      return mean + stddev * InverseNormalCdf(std::max(u, 1e-12));
  }
  return nullptr;
}

bool MetricBound::Holds(std::optional<double> value) const {
  if (!value || !std::isfinite(*value)) return false;
  // The run's expectations and a campaign's criteria compare through one evaluator.
  if (max && !scoring::Compare(*value, "<=", *max)) return false;
  if (min && !scoring::Compare(*value, ">=", *min)) return false;
  return true;
}

std::string MetricBound::Describe() const {
  if (min && max) return fmt::format("{} <= {} <= {}", *min, metric, *max);
  if (max) return fmt::format("{} <= {}", metric, *max);
  return fmt::format("{} >= {}", metric, *min);
}

std::string CampaignCriterion::Describe() const {
  if (!bound) return fmt::format("pass rate >= {:.4g} %", fraction * 100);
  return fmt::format(">= {:.4g} % of runs with {}", fraction * 100, bound->Describe());
}

namespace {

CampaignSpec ReadCampaign(const Loader& L, const YAML::Node& root) {
  const std::string& file = L.file();
  L.CheckKeys(root, "",
              {"campaign", "description", "base", "sampling", "runs", "seed", "repeats", "set",
               "parameters", "pass", "rank_by", "timeout_s"});
  CampaignSpec spec;
  spec.file = file;
  spec.name =
      root["campaign"] ? L.NonEmpty(root["campaign"], "campaign") : fs::path(file).stem().string();
  for (char c : spec.name) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.')) {
      L.Fail(root["campaign"], "campaign", "use only letters, digits, '_', '-', '.'");
    }
  }
  const fs::path dir = fs::absolute(fs::path(file)).parent_path();
  const std::string base = L.NonEmpty(root, "base", "base");
  spec.base_scenario = fs::path(base).is_absolute() ? fs::path(base) : dir / base;
  spec.base_scenario = spec.base_scenario.lexically_normal();
  // The error_code forms: a path the file system refuses (too long, a loop) is an input error.
  std::error_code ec;
  if (!fs::is_regular_file(spec.base_scenario, ec)) {
    L.Fail(root["base"], "base",
           fmt::format("scenario '{}' not found{}", spec.base_scenario.string(),
                       ec ? " (" + ec.message() + ")" : std::string()));
  }

  const std::string sampling = root["sampling"] ? L.NonEmpty(root["sampling"], "sampling") : "grid";
  if (sampling == "grid") {
    spec.sampling = CampaignSpec::Sampling::kGrid;
  } else if (sampling == "random") {
    spec.sampling = CampaignSpec::Sampling::kRandom;
  } else if (sampling == "lhs" || sampling == "latin_hypercube") {
    spec.sampling = CampaignSpec::Sampling::kLatinHypercube;
  } else {
    L.Fail(root["sampling"], "sampling", fmt::format("'{}' is not grid, random or lhs", sampling));
  }
  if (root["runs"]) spec.runs = L.Integer(root["runs"], "runs", 1);
  if (spec.sampling != CampaignSpec::Sampling::kGrid && spec.runs == 0) {
    L.Fail(root["sampling"], "runs", "random and lhs sampling need a run count `runs`");
  }
  if (root["seed"]) {
    const double s = L.ToNumber(root["seed"], "seed");
    if (s < 0 || s != std::floor(s) || s > 9.0e15)
      L.Fail(root["seed"], "seed", "must be an integer >= 0");
    spec.seed = static_cast<std::uint64_t>(s);
  }
  if (root["repeats"]) spec.repeats = L.Integer(root["repeats"], "repeats", 1);
  if (root["timeout_s"]) {
    spec.timeout_s = L.ToNumber(root["timeout_s"], "timeout_s");
    if (spec.timeout_s <= 0) L.Fail(root["timeout_s"], "timeout_s", "must be > 0");
  }

  if (const auto set = root["set"]) {
    if (!set.IsMap()) L.Fail(set, "set", "must be a mapping of path: value");
    for (const auto& kv : set) {
      Override o;
      o.path = L.KeyName(kv.first, "set");
      o.line = L.Line(kv.first);
      o.column = L.Column(kv.first);
      o.value = L.ScalarOrList(kv.second, "set." + o.path);
      spec.overrides.push_back(std::move(o));
    }
  }

  const YAML::Node params = root["parameters"];
  if (!params || !params.IsSequence() || params.size() == 0) {
    L.Fail(params ? params : root, "parameters", "needs a non-empty list of parameters");
  }
  std::set<std::string> seen_paths;
  for (std::size_t i = 0; i < params.size(); ++i) {
    const YAML::Node p = params[i];
    const std::string field = fmt::format("parameters[{}]", i);
    L.CheckKeys(p, field, {"path", "values", "range", "uniform", "normal", "loguniform"});
    ParameterSpec ps;
    ps.line = L.Line(p);
    ps.column = L.Column(p);
    const YAML::Node pp = Loader::Get(p, "path");
    if (pp.IsSequence()) {  // linked: one value, several paths
      if (pp.size() == 0) L.Fail(pp, field + ".path", "needs at least one path");
      for (std::size_t k = 0; k < pp.size(); ++k) {
        ps.paths.push_back(L.NonEmpty(pp[k], fmt::format("{}.path[{}]", field, k)));
        ps.path += (k == 0 ? "" : " + ") + ps.paths.back();
      }
    } else {
      ps.path = L.NonEmpty(p, "path", field + ".path");
      ps.paths = {ps.path};
    }
    for (const auto& one : ps.paths) {
      if (!seen_paths.insert(one).second) L.Fail(p["path"], field + ".path", "varied twice");
    }
    int kinds = 0;
    if (const auto v = p["values"]) {
      ++kinds;
      ps.kind = ParameterSpec::Kind::kList;
      if (!v.IsSequence() || v.size() == 0) L.Fail(v, field + ".values", "needs a non-empty list");
      for (const auto& e : v) ps.values.push_back(L.ScalarOrList(e, field + ".values"));
    }
    if (const auto r = p["range"]) {
      ++kinds;
      ps.kind = ParameterSpec::Kind::kRange;
      L.CheckKeys(r, field + ".range", {"from", "to", "steps"});
      ps.from = L.RequiredNumber(r, "from", field + ".range");
      ps.to = L.RequiredNumber(r, "to", field + ".range");
      ps.steps = L.Integer(r, "steps", field + ".range", 1);
    }
    if (const auto u = p["uniform"]) {
      ++kinds;
      ps.kind = ParameterSpec::Kind::kUniform;
      L.CheckKeys(u, field + ".uniform", {"min", "max"});
      ps.from = L.RequiredNumber(u, "min", field + ".uniform");
      ps.to = L.RequiredNumber(u, "max", field + ".uniform");
      if (!(ps.to > ps.from)) L.Fail(u, field + ".uniform", "needs min < max");
    }
    if (const auto u = p["loguniform"]) {
      ++kinds;
      ps.kind = ParameterSpec::Kind::kLogUniform;
      L.CheckKeys(u, field + ".loguniform", {"min", "max"});
      ps.from = L.RequiredNumber(u, "min", field + ".loguniform");
      ps.to = L.RequiredNumber(u, "max", field + ".loguniform");
      if (!(ps.from > 0 && ps.to > ps.from))
        L.Fail(u, field + ".loguniform", "needs 0 < min < max");
    }
    if (const auto n = p["normal"]) {
      ++kinds;
      ps.kind = ParameterSpec::Kind::kNormal;
      L.CheckKeys(n, field + ".normal", {"mean", "stddev"});
      ps.mean = L.RequiredNumber(n, "mean", field + ".normal");
      ps.stddev = L.RequiredNumber(n, "stddev", field + ".normal");
      if (!(ps.stddev > 0)) L.Fail(n, field + ".normal.stddev", "must be > 0");
    }
    if (kinds != 1) {
      L.Fail(p, field, "give exactly one of values, range, uniform, loguniform, normal");
    }
    const bool distribution = ps.kind == ParameterSpec::Kind::kUniform ||
                              ps.kind == ParameterSpec::Kind::kNormal ||
                              ps.kind == ParameterSpec::Kind::kLogUniform;
    if (distribution && spec.sampling == CampaignSpec::Sampling::kGrid) {
      L.Fail(p, field, "a random distribution needs `sampling: random` or `sampling: lhs`");
    }
    spec.parameters.push_back(std::move(ps));
  }

  // The run count, refused before anything is expanded or started.
  if (RunCount(spec) > CampaignSpec::kMaxRuns) {
    L.Fail(root["repeats"] ? root["repeats"] : params, root["repeats"] ? "repeats" : "parameters",
           fmt::format("more than {} runs (points x repeats); split the campaign",
                       CampaignSpec::kMaxRuns));
  }

  if (const auto pass = root["pass"]) {
    L.CheckKeys(pass, "pass", {"verdict", "run", "campaign"});
    if (pass["verdict"]) spec.require_verdict_pass = L.ToBool(pass["verdict"], "pass.verdict");
    if (const auto run = pass["run"]) {
      if (!run.IsSequence()) L.Fail(run, "pass.run", "must be a list of {metric, max|min}");
      for (std::size_t i = 0; i < run.size(); ++i) {
        spec.run_criteria.push_back(L.Bound(run[i], fmt::format("pass.run[{}]", i), {}));
      }
    }
    if (const auto camp = pass["campaign"]) {
      if (!camp.IsSequence()) L.Fail(camp, "pass.campaign", "must be a list");
      for (std::size_t i = 0; i < camp.size(); ++i) {
        const YAML::Node c = camp[i];
        const std::string field = fmt::format("pass.campaign[{}]", i);
        CampaignCriterion cc;
        cc.line = L.Line(c);
        cc.column = L.Column(c);
        if (!c.IsMap()) L.Fail(c, field, "must be a mapping");
        if (c["pass_rate"]) {
          L.CheckKeys(c, field, {"pass_rate"});
          cc.fraction = L.ToNumber(c["pass_rate"], field + ".pass_rate");
        } else {
          cc.bound = L.Bound(c, field, {"fraction"});
          cc.fraction = c["fraction"] ? L.ToNumber(c["fraction"], field + ".fraction") : 1.0;
        }
        if (cc.fraction < 0 || cc.fraction > 1) L.Fail(c, field, "fraction must be in [0, 1]");
        spec.campaign_criteria.push_back(cc);
      }
    }
  }
  if (root["rank_by"]) {
    spec.rank_metric = L.NonEmpty(root["rank_by"], "rank_by");
  } else if (!spec.run_criteria.empty()) {
    spec.rank_metric = spec.run_criteria.front().metric;
  } else {
    for (const auto& c : spec.campaign_criteria) {
      if (c.bound) {
        spec.rank_metric = c.bound->metric;
        break;
      }
    }
  }

  // Fingerprint: everything that decides which runs exist and what they do. The base is read
  // once, here, and kept: the runs are written from these bytes.
  spec.base_text = bus::yaml::FieldReader(spec.base_scenario.string()).ReadFile();
  json fp = {{"sampling", sampling},
             {"runs", spec.runs},
             {"seed", spec.seed},
             {"repeats", spec.repeats},
             {"base", Hex64(Fnv1a64(*spec.base_text))}};
  for (const auto& o : spec.overrides) fp["set"].push_back({o.path, o.value});
  for (const auto& p : spec.parameters) {
    fp["parameters"].push_back({{"path", p.path},
                                {"kind", static_cast<int>(p.kind)},
                                {"values", p.values},
                                {"a", p.from},
                                {"b", p.to},
                                {"steps", p.steps},
                                {"mean", p.mean},
                                {"sd", p.stddev}});
  }
  spec.fingerprint = Hex64(Fnv1a64(fp.dump()));
  return spec;
}

}  // namespace

CampaignSpec ParseCampaign(const std::string& yaml_text, const std::string& file) {
  const Loader L(file);
  return L.Guard([&] { return ReadCampaign(L, L.Parse(yaml_text)); });
}

CampaignSpec LoadCampaignFile(const fs::path& file) {
  return ParseCampaign(Loader(file.string()).ReadFile(), file.string());
}

json RunSpec::ParamsJson(const CampaignSpec& spec) const {
  json out = json::object();
  for (std::size_t i = 0; i < spec.parameters.size() && i < values.size(); ++i) {
    out[spec.parameters[i].path] = values[i];
  }
  return out;
}

std::size_t RunCount(const CampaignSpec& spec) {
  constexpr std::size_t kTooMany = CampaignSpec::kMaxRuns + 1;
  std::size_t points = 1;
  if (spec.sampling == CampaignSpec::Sampling::kGrid) {
    for (const auto& p : spec.parameters) {
      const std::size_t n = p.kind == ParameterSpec::Kind::kList ? p.values.size()
                                                                 : static_cast<std::size_t>(p.steps);
      points = n != 0 && points > CampaignSpec::kMaxRuns / n ? kTooMany : points * n;
    }
  } else {
    points = static_cast<std::size_t>(std::max(spec.runs, 0));
  }
  const auto repeats = static_cast<std::size_t>(std::max(spec.repeats, 1));
  return points > CampaignSpec::kMaxRuns / repeats ? kTooMany : std::min(points * repeats, kTooMany);
}

std::vector<RunSpec> ExpandRuns(const CampaignSpec& spec) {
  if (RunCount(spec) > CampaignSpec::kMaxRuns) {
    throw std::invalid_argument(fmt::format("{}: parameters: more than {} runs (points x repeats)",
                                            spec.file, CampaignSpec::kMaxRuns));
  }
  const std::size_t dims = spec.parameters.size();
  std::vector<std::vector<json>> points;
  switch (spec.sampling) {
    case CampaignSpec::Sampling::kGrid: {
      std::vector<std::vector<json>> grids;
      std::size_t total = 1;
      for (const auto& p : spec.parameters) {
        grids.push_back(p.GridValues());
        total *= grids.back().size();
      }
      // First parameter varies slowest (row-major, like nested loops in file order).
      for (std::size_t n = 0; n < total; ++n) {
        std::vector<json> point(dims);
        std::size_t rest = n;
        for (std::size_t d = dims; d-- > 0;) {
          point[d] = grids[d][rest % grids[d].size()];
          rest /= grids[d].size();
        }
        points.push_back(std::move(point));
      }
      break;
    }
    case CampaignSpec::Sampling::kRandom: {
      Rng rng(SplitMix64(spec.seed ^ 0x52414e444f4dULL));
      for (int n = 0; n < spec.runs; ++n) {
        std::vector<json> point;
        for (const auto& p : spec.parameters) point.push_back(p.FromUnit(rng.Uniform()));
        points.push_back(std::move(point));
      }
      break;
    }
    case CampaignSpec::Sampling::kLatinHypercube: {
      // Each dimension's [0, 1) is cut into `runs` equal strata; every stratum is used exactly
      // once per dimension (independent random permutation per dimension), jittered inside.
      Rng rng(SplitMix64(spec.seed ^ 0x4c4853ULL));
      const int n = spec.runs;
      points.assign(n, std::vector<json>(dims));
      for (std::size_t d = 0; d < dims; ++d) {
        std::vector<int> perm(n);
        for (int i = 0; i < n; ++i) perm[i] = i;
        for (int i = n - 1; i > 0; --i) std::swap(perm[i], perm[rng.Below(i + 1)]);
        for (int i = 0; i < n; ++i) {
          const double u = (perm[i] + rng.Uniform()) / n;
          points[i][d] = spec.parameters[d].FromUnit(u);
        }
      }
      break;
    }
  }
  std::vector<RunSpec> runs;
  runs.reserve(points.size() * spec.repeats);
  for (std::size_t p = 0; p < points.size(); ++p) {
    for (int r = 0; r < spec.repeats; ++r) {
      RunSpec run;
      run.index = static_cast<int>(runs.size());
      run.point = static_cast<int>(p);
      run.repeat = r;
      // Seeds fit in 31 bits so that every runner accepts them.
      run.seed = SplitMix64(spec.seed * 0x100000001b3ULL + p * 1000003ULL + r) & 0x7fffffffULL;
      run.values = points[p];
      json id = {{"params", run.ParamsJson(spec)}, {"seed", run.seed}, {"base", spec.fingerprint}};
      run.key = fmt::format("p{:05}-r{}-{}", p, r, Hex64(Fnv1a64(id.dump())));
      runs.push_back(std::move(run));
    }
  }
  return runs;
}

Shard Shard::Parse(const std::string& text) {
  Shard s;
  const auto slash = text.find('/');
  try {
    if (slash == std::string::npos) throw std::invalid_argument("no slash");
    std::size_t used_k = 0, used_n = 0;
    s.k = std::stoi(text.substr(0, slash), &used_k);
    s.n = std::stoi(text.substr(slash + 1), &used_n);
    if (used_k != slash || used_n != text.size() - slash - 1) throw std::invalid_argument("junk");
  } catch (const std::exception&) {
    throw std::invalid_argument(fmt::format("--shard '{}': expected K/N, e.g. 0/4", text));
  }
  if (s.n < 1 || s.k < 0 || s.k >= s.n) {
    throw std::invalid_argument(
        fmt::format("--shard '{}': need N >= 1 and 0 <= K < N (K is 0-based)", text));
  }
  return s;
}

std::vector<RunSpec> SelectShard(const std::vector<RunSpec>& runs, const Shard& shard) {
  std::vector<RunSpec> out;
  for (const auto& r : runs) {
    if (shard.Contains(r)) out.push_back(r);
  }
  return out;
}

}  // namespace wheelhil::emulator::campaign
