#include "emulator/campaign/results_store.h"

#include <fmt/format.h>
#include <sqlite3.h>

#include <cctype>
#include <stdexcept>

namespace wheelhil::emulator::campaign {
namespace {

using nlohmann::json;

constexpr const char* kSchema = R"sql(
CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs(
  key TEXT PRIMARY KEY,
  run_index INTEGER NOT NULL,
  point INTEGER NOT NULL,
  repeat INTEGER NOT NULL,
  seed INTEGER NOT NULL,
  params TEXT NOT NULL,
  verdict TEXT NOT NULL,
  passed INTEGER NOT NULL,
  failure TEXT NOT NULL,
  metrics TEXT NOT NULL,
  run_dir TEXT NOT NULL,
  scenario_path TEXT NOT NULL,
  report_path TEXT NOT NULL,
  exit_code INTEGER NOT NULL,
  wall_s REAL NOT NULL,
  finished_utc TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ','now')));
CREATE INDEX IF NOT EXISTS runs_by_index ON runs(run_index);
)sql";

class Stmt {
 public:
  Stmt(sqlite3* db, const char* sql, const std::string& file) : file_(file) {
    if (sqlite3_prepare_v2(db, sql, -1, &s_, nullptr) != SQLITE_OK) {
      throw std::runtime_error(fmt::format("{}: sqlite: {}", file, sqlite3_errmsg(db)));
    }
  }
  ~Stmt() { sqlite3_finalize(s_); }
  sqlite3_stmt* get() { return s_; }
  void Text(int i, const std::string& v) {
    sqlite3_bind_text(s_, i, v.c_str(), static_cast<int>(v.size()), SQLITE_TRANSIENT);
  }
  void Int(int i, std::int64_t v) { sqlite3_bind_int64(s_, i, v); }
  void Real(int i, double v) { sqlite3_bind_double(s_, i, v); }
  std::string ColText(int i) {
    const auto* p = sqlite3_column_text(s_, i);
    return p ? reinterpret_cast<const char*>(p) : "";
  }

 private:
  sqlite3_stmt* s_ = nullptr;
  std::string file_;
};

std::string OtherCampaign(const std::string& file, const std::string& campaign,
                          const std::string& stored, const std::string& fingerprint) {
  return fmt::format(
      "{}: holds results of campaign '{}' (fingerprint {}), not of this campaign file "
      "(fingerprint {}: the campaign file or its base scenario changed since those runs); use "
      "another --db or delete the file",
      file, campaign, stored, fingerprint);
}

// "file:" URI of `path` (RFC 3986 percent-encoding; '/' kept) with `query`.
std::string FileUri(const std::string& path, const std::string& query) {
  std::string uri = "file:";
  for (const char c : path) {
    const auto u = static_cast<unsigned char>(c);
    if (std::isalnum(u) != 0 || c == '/' || c == '-' || c == '_' || c == '.' || c == '~') {
      uri += c;
    } else {
      uri += fmt::format("%{:02X}", u);
    }
  }
  return uri + "?" + query;
}

}  // namespace

// A WAL database opened read-only still creates its -shm (and -wal) beside it; where they
// cannot be created (a read-only file system, an immutable folder) SQLite cannot open it at
// all unless told the file is immutable, which holds there: a writer would need that -shm.
void ResultsStore::OpenReadOnly() {
  int rc = SQLITE_OK;
  for (const bool immutable : {false, true}) {
    sqlite3_close(db_);
    db_ = nullptr;
    rc = sqlite3_open_v2(FileUri(file_, immutable ? "mode=ro&immutable=1" : "mode=ro").c_str(),
                         &db_, SQLITE_OPEN_READONLY | SQLITE_OPEN_URI, nullptr);
    if (rc == SQLITE_OK) {
      sqlite3_busy_timeout(db_, 30000);
      rc = sqlite3_exec(db_, "SELECT count(*) FROM sqlite_master", nullptr, nullptr, nullptr);
    }
    if ((rc & 0xFF) != SQLITE_CANTOPEN) break;  // open, or failed for another reason
  }
  if (rc != SQLITE_OK) {
    throw std::runtime_error(
        fmt::format("{}: sqlite: {}", file_, db_ ? sqlite3_errmsg(db_) : "out of memory"));
  }
  Stmt s(db_,
         "SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name IN ('meta', 'runs')",
         file_);
  has_tables_ = sqlite3_step(s.get()) == SQLITE_ROW && sqlite3_column_int(s.get(), 0) == 2;
}

ResultsStore::ResultsStore(const std::filesystem::path& file, const std::string& campaign_name,
                           const std::string& fingerprint, Access access)
    : file_(file.string()) {
  if (access == Access::kReadOnly) {
    try {
      OpenReadOnly();
      const std::string stored = Meta("fingerprint");
      if (!fingerprint.empty() && !stored.empty() && stored != fingerprint) {
        throw std::runtime_error(OtherCampaign(file_, Meta("campaign"), stored, fingerprint));
      }
    } catch (...) {
      sqlite3_close(db_);
      db_ = nullptr;
      throw;
    }
    return;
  }
  if (file.has_parent_path()) std::filesystem::create_directories(file.parent_path());
  if (sqlite3_open(file_.c_str(), &db_) != SQLITE_OK) {
    const std::string msg = db_ ? sqlite3_errmsg(db_) : "out of memory";
    sqlite3_close(db_);
    db_ = nullptr;
    throw std::runtime_error(fmt::format("{}: sqlite: {}", file_, msg));
  }
  try {
    sqlite3_busy_timeout(db_, 30000);
    // WAL + synchronous=NORMAL: a committed transaction survives the process being killed at
    // any moment (only an OS crash or power loss can lose the last commits).
    Exec("PRAGMA journal_mode=WAL");
    Exec("PRAGMA synchronous=NORMAL");
    Exec(kSchema);
    const std::string stored = Meta("fingerprint");
    if (!fingerprint.empty()) {
      if (stored.empty()) {
        Exec("BEGIN IMMEDIATE");
        Stmt s(db_, "INSERT OR REPLACE INTO meta(key, value) VALUES (?1, ?2)", file_);
        for (const auto& [k, v] : {std::pair<std::string, std::string>{"fingerprint", fingerprint},
                                   {"campaign", campaign_name}}) {
          sqlite3_reset(s.get());
          s.Text(1, k);
          s.Text(2, v);
          if (sqlite3_step(s.get()) != SQLITE_DONE) {
            throw std::runtime_error(fmt::format("{}: sqlite: {}", file_, sqlite3_errmsg(db_)));
          }
        }
        Exec("COMMIT");
      } else if (stored != fingerprint) {
        throw std::runtime_error(OtherCampaign(file_, Meta("campaign"), stored, fingerprint));
      }
    }
  } catch (...) {
    sqlite3_close(db_);
    db_ = nullptr;
    throw;
  }
}

ResultsStore::~ResultsStore() { sqlite3_close(db_); }

void ResultsStore::Exec(const std::string& sql) const {
  char* err = nullptr;
  if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
    const std::string msg = err ? err : "unknown error";
    sqlite3_free(err);
    throw std::runtime_error(fmt::format("{}: sqlite: {}", file_, msg));
  }
}

std::string ResultsStore::Meta(const std::string& key) const {
  if (!has_tables_) return "";
  Stmt s(db_, "SELECT value FROM meta WHERE key = ?1", file_);
  s.Text(1, key);
  if (sqlite3_step(s.get()) == SQLITE_ROW) return s.ColText(0);
  return "";
}

std::set<std::string> ResultsStore::StoredKeys() const {
  std::set<std::string> keys;
  if (!has_tables_) return keys;
  Stmt s(db_, "SELECT key FROM runs", file_);
  while (sqlite3_step(s.get()) == SQLITE_ROW) keys.insert(s.ColText(0));
  return keys;
}

void ResultsStore::Put(const RunRecord& r) {
  if (sqlite3_db_readonly(db_, "main") == 1) {
    throw std::runtime_error(
        fmt::format("{}: opened read-only, cannot store run {}", file_, r.key));
  }
  Exec("BEGIN IMMEDIATE");
  try {
    Stmt s(db_,
           "INSERT OR IGNORE INTO runs(key, run_index, point, repeat, seed, params, verdict, "
           "passed, failure, metrics, run_dir, scenario_path, report_path, exit_code, wall_s) "
           "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15)",
           file_);
    s.Text(1, r.key);
    s.Int(2, r.index);
    s.Int(3, r.point);
    s.Int(4, r.repeat);
    s.Int(5, static_cast<std::int64_t>(r.seed));
    s.Text(6, r.params.dump());
    s.Text(7, r.verdict);
    s.Int(8, r.passed ? 1 : 0);
    s.Text(9, r.failure);
    s.Text(10, json(r.metrics).dump());
    s.Text(11, r.run_dir);
    s.Text(12, r.scenario_path);
    s.Text(13, r.report_path);
    s.Int(14, r.exit_code);
    s.Real(15, r.wall_s);
    if (sqlite3_step(s.get()) != SQLITE_DONE) {
      throw std::runtime_error(fmt::format("{}: sqlite: {}", file_, sqlite3_errmsg(db_)));
    }
  } catch (...) {
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    throw;
  }
  Exec("COMMIT");
}

std::vector<RunRecord> ResultsStore::All() const {
  std::vector<RunRecord> out;
  if (!has_tables_) return out;
  Stmt s(db_,
         "SELECT key, run_index, point, repeat, seed, params, verdict, passed, failure, metrics, "
         "run_dir, scenario_path, report_path, exit_code, wall_s FROM runs "
         "ORDER BY run_index, key",
         file_);
  while (sqlite3_step(s.get()) == SQLITE_ROW) {
    RunRecord r;
    r.key = s.ColText(0);
    r.index = sqlite3_column_int(s.get(), 1);
    r.point = sqlite3_column_int(s.get(), 2);
    r.repeat = sqlite3_column_int(s.get(), 3);
    r.seed = static_cast<std::uint64_t>(sqlite3_column_int64(s.get(), 4));
    r.params = json::parse(s.ColText(5), nullptr, false);
    if (r.params.is_discarded()) r.params = json::object();
    r.verdict = s.ColText(6);
    r.passed = sqlite3_column_int(s.get(), 7) != 0;
    r.failure = s.ColText(8);
    const json m = json::parse(s.ColText(9), nullptr, false);
    if (m.is_object()) {
      for (const auto& [k, v] : m.items()) {
        if (v.is_number()) r.metrics[k] = v.get<double>();
      }
    }
    r.run_dir = s.ColText(10);
    r.scenario_path = s.ColText(11);
    r.report_path = s.ColText(12);
    r.exit_code = sqlite3_column_int(s.get(), 13);
    r.wall_s = sqlite3_column_double(s.get(), 14);
    out.push_back(std::move(r));
  }
  return out;
}

std::size_t MergeStores(const std::filesystem::path& out,
                        const std::vector<std::filesystem::path>& inputs) {
  if (inputs.empty()) throw std::runtime_error("campaign merge: no input databases");
  std::string fingerprint, name;
  for (const auto& in : inputs) {
    if (!std::filesystem::is_regular_file(in)) {
      throw std::runtime_error(fmt::format("{}: no such database", in.string()));
    }
    ResultsStore probe(in, "", "");
    const std::string fp = probe.Meta("fingerprint");
    if (fingerprint.empty()) {
      fingerprint = fp;
      name = probe.Meta("campaign");
    } else if (fp != fingerprint) {
      throw std::runtime_error(fmt::format(
          "{}: campaign fingerprint {} differs from {} ({}): shards of different campaigns",
          in.string(), fp, fingerprint, inputs.front().string()));
    }
  }
  ResultsStore dest(out, name, fingerprint);
  for (const auto& in : inputs) {
    if (std::filesystem::exists(out) && std::filesystem::equivalent(in, out)) continue;
    ResultsStore src(in, "", "");
    for (const auto& r : src.All()) dest.Put(r);
  }
  return dest.All().size();
}

}  // namespace wheelhil::emulator::campaign
