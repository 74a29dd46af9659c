#pragma once
/// SQLite results store of a campaign: one row per finished run (parameters, verdict, metrics,
/// artefact paths), written in WAL mode with one transaction per run, so a campaign killed at
/// any moment (SIGKILL included) loses at most the runs still in flight; a run is either fully
/// stored or absent. Resume = skip runs whose key is stored. `meta` holds the campaign's name
/// and fingerprint; opening a store with a different campaign fingerprint is refused, so two
/// campaigns never mix in one file. Not thread-safe: one ResultsStore per thread (SQLite itself
/// serialises writers across processes; busy timeout 30 s).

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

struct sqlite3;

namespace wheelhil::emulator::campaign {

struct RunRecord {
  std::string key;
  int index = 0;
  int point = 0;
  int repeat = 0;
  std::uint64_t seed = 0;
  nlohmann::json params = nlohmann::json::object();  ///< {"path": value}
  std::string verdict;  ///< runner's verdict, or "error" / "timeout" when no report came
  bool passed = false;  ///< verdict and the campaign's per-run criteria
  std::string failure;  ///< why not passed (failed expectations / criteria / runner error)
  std::map<std::string, double> metrics;
  std::string run_dir, scenario_path, report_path;
  int exit_code = 0;
  double wall_s = 0;  ///< wall-clock duration (never compared between runs)
};

class ResultsStore {
 public:
  enum class Access : std::uint8_t {
    kReadWrite,
    /// Reads an existing file without writing anything, -wal and -shm files included where they
    /// cannot be created (a read-only file system), so that finished results can be summarised
    /// wherever they are. Put() throws.
    kReadOnly,
  };
  /// Opens or creates `file` (kReadOnly: opens it; a file without the tables reads as empty).
  /// With a non-empty `fingerprint`, records it on creation and throws std::runtime_error if
  /// the file holds another campaign. Throws std::runtime_error on SQLite errors.
  ResultsStore(const std::filesystem::path& file, const std::string& campaign_name,
               const std::string& fingerprint, Access access = Access::kReadWrite);
  ~ResultsStore();
  ResultsStore(const ResultsStore&) = delete;
  ResultsStore& operator=(const ResultsStore&) = delete;

  std::set<std::string> StoredKeys() const;
  /// Stores one run in its own transaction (INSERT OR IGNORE: a stored run is never replaced).
  void Put(const RunRecord& record);
  /// All runs, ordered by run index.
  std::vector<RunRecord> All() const;
  std::string Meta(const std::string& key) const;  ///< "" when absent

 private:
  void Exec(const std::string& sql) const;
  void OpenReadOnly();
  sqlite3* db_ = nullptr;
  std::string file_;
  bool has_tables_ = true;  ///< kReadOnly: false for a file without the schema
};

/// `wheelhil campaign merge OUT IN...`: copies every run of the inputs into OUT (created if
/// needed). All inputs must carry the same campaign fingerprint. Returns the number of runs in
/// OUT afterwards. Throws std::runtime_error.
std::size_t MergeStores(const std::filesystem::path& out,
                        const std::vector<std::filesystem::path>& inputs);

}  // namespace wheelhil::emulator::campaign
