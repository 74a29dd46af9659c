// End-to-end campaign tests on the fake runner (tests/emulator/campaign/fake_wheelhil_run.cc, a test
// double of `wheelhil run`): resume after SIGKILL, shards merged == unsharded, JUnit XML against
// the schema, reports, smoke.

#include "emulator/campaign/campaign.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <thread>

#include "emulator/campaign/junit_writer.h"
#include "emulator/campaign/results_store.h"
#include "emulator/campaign/run_report.h"
#include "emulator/xml_escape.h"
#include "tests/emulator/campaign/campaign_test_util.h"
#include "tests/emulator/scoring/text_checks.h"

namespace wheelhil::emulator::campaign {
namespace {

using ::testing::HasSubstr;
using testing::kBaseScenario;
using testing::TempDir;
namespace fs = std::filesystem;

constexpr const char* kCampaign = R"(campaign: fake_envelope
base: base.yaml
sampling: grid
repeats: 2
seed: 11
parameters:
  - path: terrain.friction
    values: [0.25, 0.5, 1.0]
  - path: faults[0].probability
    range: {from: 0.0, to: 0.3, steps: 4}
pass:
  run:
    - {metric: pose.final_heading_error_rad, max: 0.01}
  campaign:
    - {pass_rate: 0.5}
    - {metric: pose.final_position_error_m, max: 0.1, fraction: 0.95}
rank_by: pose.final_position_error_m
)";

std::string ReadAll(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// What must agree between two executions of the same campaign (no wall-clock, no paths).
std::map<std::string, std::string> Comparable(const std::vector<RunRecord>& runs) {
  std::map<std::string, std::string> out;
  for (const auto& r : runs) {
    out[r.key] =
        nlohmann::json{{"index", r.index},     {"seed", r.seed},     {"params", r.params},
                       {"verdict", r.verdict}, {"passed", r.passed}, {"failure", r.failure},
                       {"metrics", r.metrics}}
            .dump();
  }
  return out;
}

class CampaignTest : public ::testing::Test {
 protected:
  CampaignTest() {
    dir_.Write("base.yaml", kBaseScenario);
    campaign_file_ = dir_.Write("camp.yaml", kCampaign);
  }
  CampaignOptions Options(const std::string& name) {
    CampaignOptions o;
    o.out_dir = dir_.path() / name;
    o.jobs = 2;
    o.runner_exe = FAKE_RUNNER;
    o.progress = false;
    return o;
  }
  TempDir dir_;
  fs::path campaign_file_;
};

TEST_F(CampaignTest, RunsStoresAndSummarises) {
  const auto spec = LoadCampaignFile(campaign_file_);
  auto o = Options("plain");
  o.junit = dir_.path() / "plain.xml";
  const auto out = RunCampaign(spec, o);
  ASSERT_EQ(out.runs.size(), 24u);
  EXPECT_EQ(out.ran_now, 24u);
  EXPECT_EQ(out.skipped, 0u);
  // error = 0.01 + 0.2 p / mu + 0.005 u: passes (< 0.1) unless p / mu >= 0.45.
  std::size_t expect_pass = 0;
  for (const auto& r : out.runs) {
    const double mu = r.params["terrain.friction"].get<double>();
    const double p = r.params["faults[0].probability"].get<double>();
    const bool pass = 0.2 * p / mu < 0.085;
    expect_pass += pass;
    EXPECT_EQ(r.passed, pass) << r.key << " " << r.failure;
    if (!r.passed) {
      EXPECT_THAT(r.failure, HasSubstr("expectation pose.final_position_error_m failed"));
    }
    EXPECT_TRUE(fs::exists(fs::path(r.run_dir) / "scenario.yaml"));
    EXPECT_NEAR(r.metrics.at("pose.final_position_error_m"), 0.01 + 0.2 * p / mu, 0.0051);
  }
  EXPECT_EQ(out.summary.passed, expect_pass);
  EXPECT_TRUE(out.summary.complete);
  ASSERT_EQ(out.summary.criteria.size(), 2u);
  EXPECT_DOUBLE_EQ(out.summary.criteria[0].achieved, static_cast<double>(expect_pass) / 24);
  EXPECT_FALSE(out.summary.criteria[1].holds) << "95 % within 0.1 m cannot hold";
  EXPECT_FALSE(out.summary.campaign_passed);
  // Worst run first: the highest slip-to-friction ratio.
  const auto& worst = out.runs[out.summary.worst.at(0)];
  EXPECT_DOUBLE_EQ(worst.params["terrain.friction"].get<double>(), 0.25);
  EXPECT_DOUBLE_EQ(worst.params["faults[0].probability"].get<double>(), 0.3);
  EXPECT_THAT(out.text, HasSubstr("terrain.friction:"));
  EXPECT_THAT(out.text, HasSubstr("faults[0].probability:"));
  const std::string html = ReadAll(o.out_dir / "campaign.html");
  EXPECT_THAT(html, HasSubstr("<svg"));
  EXPECT_THAT(html, HasSubstr("fake_envelope"));
  // Parameter-vs-metric plots draw the criterion's limit (0.1 m) with its value and unit, and
  // the table cells and ticks are rounded, never in exponent notation.
  EXPECT_THAT(html, HasSubstr("class=\"threshold\""));
  EXPECT_THAT(html, HasSubstr("pass limit 100 mm"));
  EXPECT_THAT(html, HasSubstr(" mm</td>"));
  const std::size_t exponent = scoring::testing::FindExponent(html);  // no "1e-05" anywhere
  EXPECT_EQ(exponent, std::string::npos) << html.substr(exponent - 1, 12);
  EXPECT_THAT(ReadAll(o.junit), HasSubstr("tests=\"26\""));

  // Same command again: everything already stored, nothing runs, same results.
  const auto again = RunCampaign(spec, o);
  EXPECT_EQ(again.ran_now, 0u);
  EXPECT_EQ(again.skipped, 24u);
  EXPECT_EQ(Comparable(again.runs), Comparable(out.runs));
}

TEST_F(CampaignTest, ResumeAfterRepeatedSigkillMatchesUninterruptedRun) {
  // Slow runs so that kills land mid-run; every kill waits for progress, not for a clock.
  dir_.Write("base.yaml",
             std::string(kBaseScenario)
                 .replace(std::string(kBaseScenario).find("sleep_s: 0.0"), 12, "sleep_s: 0.03"));
  const auto spec = LoadCampaignFile(campaign_file_);
  const fs::path db = dir_.path() / "killed.sqlite";
  const fs::path log = dir_.path() / "executions.log";
  ::setenv("FAKE_WHEELHIL_RUN_LOG", log.c_str(), 1);
  const std::string out_dir = (dir_.path() / "killed").string();
  std::vector<std::string> args = {WHEELHIL_EXE, "campaign",  campaign_file_.string(),
                                   "--jobs",     "2",         "--db",
                                   db.string(),  "--out",     out_dir,
                                   "--runner",   FAKE_RUNNER, "--quiet",
                                   "--no-html"};
  auto spawn = [&] {
    const pid_t pid = ::fork();
    if (pid == 0) {
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      const int null_fd = ::open("/dev/null", O_WRONLY);
      ::dup2(null_fd, STDOUT_FILENO);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    return pid;
  };
  auto stored_keys = [&] {
    if (!fs::exists(db)) return std::set<std::string>{};
    ResultsStore s(db, "", "");
    return s.StoredKeys();
  };
  auto log_lines = [&] {
    std::vector<std::string> lines;
    std::ifstream in(log);
    for (std::string l; std::getline(in, l);) lines.push_back(l);
    return lines;
  };
  std::mt19937 rng(5);
  int kills_mid_run = 0;
  std::vector<std::pair<std::set<std::string>, std::size_t>> snapshots;
  for (int attempt = 0; attempt < 5; ++attempt) {
    const std::size_t before = stored_keys().size();
    const std::size_t wait_for = before + 1 + rng() % 4;
    const pid_t pid = spawn();
    ASSERT_GT(pid, 0);
    int status = 0;
    bool exited = false;
    while (!exited && stored_keys().size() < wait_for) {
      exited = ::waitpid(pid, &status, WNOHANG) == pid;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    if (!exited) {
      // Let it get a random bit further into the next runs, then kill it hard.
      std::this_thread::sleep_for(std::chrono::milliseconds(rng() % 25));
      ::kill(pid, SIGKILL);
      ASSERT_EQ(::waitpid(pid, &status, 0), pid);
      if (WIFSIGNALED(status)) ++kills_mid_run;
    }
    snapshots.emplace_back(stored_keys(), log_lines().size());
  }
  EXPECT_GE(kills_mid_run, 3);
  const pid_t last = spawn();
  int status = 0;
  ASSERT_EQ(::waitpid(last, &status, 0), last);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1) << "criteria fail (as in the uninterrupted run)";
  ::unsetenv("FAKE_WHEELHIL_RUN_LOG");

  // Finished runs are never repeated: no run stored at a kill ran again afterwards.
  const auto lines = log_lines();
  for (const auto& [keys, first_line] : snapshots) {
    for (std::size_t i = first_line; i < lines.size(); ++i) {
      const std::string key = fs::path(lines[i]).filename().string();
      EXPECT_EQ(keys.count(key), 0u) << key << " ran again after it was stored";
    }
  }
  // ... and none are lost: the interrupted campaign equals an uninterrupted one.
  ResultsStore killed(db, "", "");
  auto o = Options("clean");
  const auto clean = RunCampaign(spec, o);
  ASSERT_EQ(killed.All().size(), 24u);
  EXPECT_EQ(Comparable(killed.All()), Comparable(clean.runs));
}

TEST_F(CampaignTest, MergedShardsEqualTheUnshardedCampaign) {
  const auto spec = LoadCampaignFile(campaign_file_);
  const auto whole = RunCampaign(spec, Options("whole"));
  std::vector<fs::path> dbs;
  for (int k = 0; k < 3; ++k) {
    auto o = Options("shards");  // one output folder shared by the shards, one db each
    o.shard = Shard::Parse(fmt::format("{}/3", k));
    o.db = dir_.path() / fmt::format("shard-{}.sqlite", k);
    o.jobs = 1;
    const auto part = RunCampaign(spec, o);
    EXPECT_EQ(part.runs.size(), 8u);
    EXPECT_TRUE(part.summary.complete);
    dbs.push_back(o.db);
  }
  const fs::path merged = dir_.path() / "merged.sqlite";
  EXPECT_EQ(MergeStores(merged, dbs), 24u);
  EXPECT_EQ(MergeStores(merged, dbs), 24u) << "merging twice changes nothing";
  ResultsStore m(merged, "", "");
  EXPECT_EQ(Comparable(m.All()), Comparable(whole.runs));
  // The campaign over the merged db runs nothing and reaches the same summary.
  auto o = Options("shards");
  o.db = merged;
  const auto summary = RunCampaign(spec, o);
  EXPECT_EQ(summary.ran_now, 0u);
  EXPECT_EQ(summary.summary.passed, whole.summary.passed);
  EXPECT_EQ(summary.summary.worst, whole.summary.worst);

  // Shards of another campaign are refused.
  TempDir other;
  other.Write("base.yaml", kBaseScenario);
  auto other_spec =
      ParseCampaign("base: base.yaml\nparameters: [{path: terrain.friction, values: [0.3]}]\n",
                    (other.path() / "c.yaml").string());
  auto oo = Options("other");
  oo.db = other.path() / "other.sqlite";
  RunCampaign(other_spec, oo);
  EXPECT_THROW(MergeStores(dir_.path() / "mixed.sqlite", {dbs[0], oo.db}), std::runtime_error);
  EXPECT_THROW(ResultsStore(oo.db, spec.name, spec.fingerprint), std::runtime_error);
}

TEST_F(CampaignTest, JUnitXmlValidatesAgainstTheSchema) {
  if (std::system("command -v xmllint >/dev/null 2>&1") != 0) {
    GTEST_SKIP() << "xmllint not installed (Debian package libxml2-utils, in ./hil PACKAGES)";
  }
  const auto spec = LoadCampaignFile(campaign_file_);
  auto o = Options("junit");
  o.junit = dir_.path() / "campaign.xml";
  RunCampaign(spec, o);
  const std::string xsd = std::string(WHEELHIL_SOURCE_DIR) + "/tests/data/junit/junit.xsd";
  const std::string cmd = "xmllint --noout --schema " + xsd + " " + o.junit.string() + " 2>&1";
  EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const std::string xml = ReadAll(o.junit);
  EXPECT_THAT(xml, HasSubstr("<failure message=\"expectation pose.final_position_error_m failed"));

  // Hostile text is escaped; control characters dropped.
  const fs::path odd = dir_.path() / "odd.xml";
  WriteJUnit(odd,
             {{"s<&>\"'",
               {{"c", "n\x01<a>", 1.5, "fail & \"quote\"\nsecond line", "", "out]]>"},
                {"c", "err", 0, "", "no report", ""},
                {"c", "ok", 0.25, "", "", ""}}}},
             "all");
  const std::string cmd2 = "xmllint --noout --schema " + xsd + " " + odd.string() + " 2>&1";
  EXPECT_EQ(std::system(cmd2.c_str()), 0) << ReadAll(odd);
  const std::string text = ReadAll(odd);
  EXPECT_THAT(text, HasSubstr("tests=\"3\" failures=\"1\" errors=\"1\""));
  EXPECT_THAT(text, HasSubstr("message=\"fail &amp; &quot;quote&quot;\""));
}

TEST_F(CampaignTest, RunnerWithoutReportIsAnErrorNamingItsLog) {
  dir_.Write("base.yaml", std::string(kBaseScenario) + "  exit_without_report: true\n");
  const auto spec = LoadCampaignFile(campaign_file_);
  const auto out = RunCampaign(spec, Options("crash"));
  ASSERT_EQ(out.runs.size(), 24u);
  for (const auto& r : out.runs) {
    EXPECT_EQ(r.verdict, "error");
    EXPECT_FALSE(r.passed);
    EXPECT_EQ(r.exit_code, 3);
    EXPECT_THAT(r.failure, HasSubstr("runner.log: fake_wheelhil_run: simulated crash"));
  }
}

// A runner script: `body` (sh), then the fake runner with the campaign's arguments.
fs::path RunnerScript(const TempDir& dir, const std::string& name, const std::string& body) {
  const fs::path p = dir.Write(name, "#!/bin/sh\n" + body + "\nexec '" FAKE_RUNNER "' \"$@\"\n");
  fs::permissions(p, fs::perms::owner_all);
  return p;
}

// The base scenario edited while the campaign runs (the next experiment's version saved over
// it): the runs still to start used the edited file under the first fingerprint. They are
// written from the base as the campaign read it.
TEST_F(CampaignTest, ABaseScenarioEditedWhileRunningChangesNoRun) {
  const auto spec = LoadCampaignFile(campaign_file_);
  const fs::path base = dir_.path() / "base.yaml";
  // Before each run: the scenario of this run is written, those of the later ones are not.
  const fs::path runner =
      RunnerScript(dir_, "editing_runner.sh",
                   "sed -i 's/limit_m: 0.1$/limit_m: 0.0001/' '" + base.string() + "'");
  auto o = Options("edited");
  o.runner_exe = runner.string();
  o.jobs = 1;
  const auto out = RunCampaign(spec, o);
  ASSERT_THAT(ReadAll(base), HasSubstr("limit_m: 0.0001"));  // the edit happened
  ASSERT_EQ(out.runs.size(), 24u);
  for (const auto& r : out.runs) {
    const std::string scenario = ReadAll(fs::path(r.run_dir) / "scenario.yaml");
    EXPECT_THAT(scenario, HasSubstr("limit_m: 0.1\n")) << r.key;
  }
  // Same verdicts as the campaign on the unedited base.
  dir_.Write("base.yaml", kBaseScenario);
  EXPECT_EQ(Comparable(out.runs), Comparable(RunCampaign(spec, Options("unedited")).runs));
  // Resumed with the edited base, the results are another campaign's: refused, saying why.
  dir_.Write("base.yaml", std::string(kBaseScenario) + "# edited\n");
  EXPECT_THAT([&] { RunCampaign(LoadCampaignFile(campaign_file_), Options("edited")); },
              ::testing::ThrowsMessage<std::runtime_error>(
                  HasSubstr("the campaign file or its base scenario changed since those runs")));
}

// Makes a folder and what it holds unwritable for this process, root included: chattr +i for
// root (file modes do not stop root; an immutable folder takes no new file, so no SQLite -shm
// or -wal either), chmod for anyone else. Undone when it goes.
class ReadOnlyFolder {
 public:
  explicit ReadOnlyFolder(const fs::path& dir) : dir_(dir) {
    for (const auto& e : fs::directory_iterator(dir)) paths_ += " '" + e.path().string() + "'";
    paths_ += " '" + dir.string() + "'";
    const std::string cmd = (::geteuid() == 0 ? "chattr +i" : "chmod a-w") + paths_ + " 2>&1";
    if (std::system(cmd.c_str()) != 0) {
      why_ = cmd + " failed (a file system without the immutable attribute?)";
      return;
    }
    applied_ = true;
    const int fd = ::open((dir / "probe").c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0600);
    if (fd >= 0) {
      ::close(fd);
      why_ = cmd + " did not stop a file being created in " + dir.string();
    }
  }
  ~ReadOnlyFolder() {
    if (!applied_) return;
    const std::string cmd = (::geteuid() == 0 ? "chattr -i" : "chmod u+w") + paths_;
    if (std::system(cmd.c_str()) != 0) ADD_FAILURE() << cmd;
    std::error_code ec;
    fs::remove(dir_ / "probe", ec);
  }
  ReadOnlyFolder(const ReadOnlyFolder&) = delete;
  ReadOnlyFolder& operator=(const ReadOnlyFolder&) = delete;
  const std::string& why_not() const { return why_; }

 private:
  fs::path dir_;
  std::string paths_;
  bool applied_ = false;
  std::string why_;
};

// Finished results on a read-only file system (an archive, a colleague's share) could not even
// be summarised: the store was opened for writing. With nothing left to run it is read-only,
// and nothing is created beside it.
TEST_F(CampaignTest, AFinishedCampaignIsSummarisedFromAReadOnlyFolder) {
  const auto spec = LoadCampaignFile(campaign_file_);
  auto o = Options("ro");
  o.db = dir_.path() / "archive" / "results.sqlite";
  const auto first = RunCampaign(spec, o);
  ASSERT_EQ(first.ran_now, 24u);
  auto listing = [&] {
    std::set<std::string> names;
    for (const auto& e : fs::directory_iterator(o.db.parent_path())) {
      names.insert(e.path().filename().string());
    }
    return names;
  };
  ASSERT_EQ(listing(), std::set<std::string>{"results.sqlite"});
  const ReadOnlyFolder archive(o.db.parent_path());
  if (!archive.why_not().empty()) GTEST_SKIP() << archive.why_not();
  o.junit = dir_.path() / "ro.xml";
  const auto again = RunCampaign(spec, o);
  EXPECT_EQ(again.ran_now, 0u);
  EXPECT_EQ(again.skipped, 24u);
  EXPECT_EQ(Comparable(again.runs), Comparable(first.runs));
  EXPECT_EQ(again.text, first.text);
  EXPECT_THAT(ReadAll(o.junit), HasSubstr("tests=\"26\""));
  EXPECT_EQ(listing(), std::set<std::string>{"results.sqlite"});
  // Another campaign's file is refused as before, read-only or not.
  std::string three = kCampaign;
  three.replace(three.find("repeats: 2"), 10, "repeats: 3");
  const fs::path other = dir_.Write("other.yaml", three);
  EXPECT_THAT([&] { RunCampaign(LoadCampaignFile(other), o); },
              ::testing::ThrowsMessage<std::runtime_error>(
                  HasSubstr(o.db.string() + ": holds results of campaign 'fake_envelope'")));
}

// A runner's load error can hold any bytes (a path or a value in Latin-1): the JUnit file
// carried them as they were, which no XML parser accepts. They become U+FFFD.
TEST_F(CampaignTest, JUnitOfALoadErrorThatIsNotUtf8IsWellFormed) {
  if (std::system("command -v xmllint >/dev/null 2>&1") != 0) {
    GTEST_SKIP() << "xmllint not installed (Debian package libxml2-utils, in ./hil PACKAGES)";
  }
  const fs::path runner = RunnerScript(
      dir_, "latin1_runner.sh",
      "printf 'scenario.yaml:3:7: name: caf\\351 \\377\\376 is not valid\\n' >&2; exit 2");
  const auto spec = LoadCampaignFile(campaign_file_);
  auto o = Options("latin1");
  o.runner_exe = runner.string();
  o.junit = dir_.path() / "latin1.xml";
  const auto out = RunCampaign(spec, o);
  ASSERT_EQ(out.runs.size(), 24u);
  EXPECT_THAT(out.runs[0].failure, HasSubstr("caf\xE9 \xFF\xFE is not valid"));  // stored as is
  const std::string xsd = std::string(WHEELHIL_SOURCE_DIR) + "/tests/data/junit/junit.xsd";
  const std::string cmd = "xmllint --noout --schema " + xsd + " " + o.junit.string() + " 2>&1";
  EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
  EXPECT_THAT(ReadAll(o.junit),
              HasSubstr("name: caf\xEF\xBF\xBD \xEF\xBF\xBD\xEF\xBF\xBD is not valid"));
  EXPECT_THAT(ReadAll(o.out_dir / "campaign.html"), HasSubstr("caf\xEF\xBF\xBD"));
  // Well-formed UTF-8 is kept; a cut long message does not split a character.
  EXPECT_EQ(EscapeXml("gr\xC3\xBC\xC3\x9F \xF0\x9F\x9A\x97 \xEF\xBF\xBE \xED\xA0\x80 \xC0\xAF"),
            "gr\xC3\xBC\xC3\x9F \xF0\x9F\x9A\x97 \xEF\xBF\xBD \xEF\xBF\xBD\xEF\xBF\xBD\xEF\xBF\xBD "
            "\xEF\xBF\xBD\xEF\xBF\xBD");
  const std::string xml =
      JUnitXml({{"s", {{"c", "n", 0, std::string(499, 'a') + "\xC3\xBC", "", ""}}}}, "all");
  EXPECT_THAT(xml, HasSubstr("message=\"" + std::string(499, 'a') + "...\""));
}

TEST_F(CampaignTest, RunReportFlattensMetricsAndNamesFailedExpectations) {
  std::string err;
  const auto r = ParseRunReport(R"({"scenario":"s","seed":3,"verdict":"fail",
    "expectations":[{"metric":"pose.final_position_error_m","op":"<","value":0.1,"actual":0.3,
                     "passed":false},{"metric":"slip.detected","op":">=","value":1,"passed":true}],
    "metrics":{"pose":{"final_position_error_m":0.3,"ok":true},"bus":{"lost":[1,2]}},
    "wall_clock":{"duration_s":1.5}})",
                                &err);
  ASSERT_TRUE(r) << err;
  EXPECT_FALSE(r->VerdictPassed());
  EXPECT_DOUBLE_EQ(r->metrics.at("pose.final_position_error_m"), 0.3);
  EXPECT_DOUBLE_EQ(r->metrics.at("pose.ok"), 1.0);
  EXPECT_DOUBLE_EQ(r->metrics.at("bus.lost[1]"), 2.0);
  EXPECT_EQ(r->metrics.count("wall_clock.duration_s"), 0u);
  EXPECT_EQ(r->FailedExpectations(),
            "expectation pose.final_position_error_m failed: actual=0.3 metric="
            "pose.final_position_error_m op=< value=0.1");
  // `wheelhil run`'s shape: the expectation's own text, the measured value, a run failure.
  const auto t = ParseRunReport(R"json({"verdict":"fail","failure":"firmware exited (code 3)",
    "expectations":[{"text":"pose.final_position_error_m < 0.1","passed":false,"value":0.31}]})json",
                                &err);
  ASSERT_TRUE(t) << err;
  EXPECT_EQ(t->FailedExpectations(),
            "run failed: firmware exited (code 3); expectation failed: "
            "pose.final_position_error_m < 0.1 (value 0.31)");
  EXPECT_FALSE(ParseRunReport("{not json", &err));
  EXPECT_FALSE(ParseRunReport(R"({"metrics":{}})", &err));
  EXPECT_THAT(err, HasSubstr("verdict"));
}

TEST_F(CampaignTest, SmokeWritesOneCasePerScenarioWithTheFailedExpectation) {
  dir_.Write("smoke/a_pass.yaml", kBaseScenario);
  std::string failing = kBaseScenario;
  failing.replace(failing.find("limit_m: 0.1"), 12, "limit_m: 0.001");
  dir_.Write("smoke/b_fail.yaml", failing);
  SmokeOptions o;
  o.scenarios = FindSmokeScenarios(dir_.path() / "smoke");
  ASSERT_EQ(o.scenarios.size(), 2u);
  o.out_dir = dir_.path() / "smoke_out";
  o.runner_exe = FAKE_RUNNER;
  o.junit = dir_.path() / "smoke.xml";
  o.firmware_command = "my-firmware --can ${CAN}";
  o.progress = false;
  const auto out = RunSmoke(o);
  EXPECT_FALSE(out.passed);
  ASSERT_EQ(out.runs.size(), 2u);
  EXPECT_TRUE(out.runs[0].passed);
  EXPECT_FALSE(out.runs[1].passed);
  const std::string xml = ReadAll(o.junit);
  EXPECT_THAT(xml, HasSubstr("name=\"b_fail\""));
  EXPECT_THAT(xml, HasSubstr("<failure message=\"expectation pose.final_position_error_m failed"));
  const std::string scen = ReadAll(fs::path(out.runs[0].run_dir) / "scenario.yaml");
  EXPECT_THAT(scen, HasSubstr("my-firmware --can ${CAN}"));
  // A list file works as well; a missing entry names the list line.
  dir_.Write("smoke.list", "# smoke\nsmoke/a_pass.yaml\n");
  EXPECT_EQ(FindSmokeScenarios(dir_.path() / "smoke.list").size(), 1u);
  dir_.Write("bad.list", "smoke/a_pass.yaml\nsmoke/none.yaml\n");
  EXPECT_THAT([&] { FindSmokeScenarios(dir_.path() / "bad.list"); },
              ::testing::ThrowsMessage<std::invalid_argument>(HasSubstr("bad.list:2:")));
}

// The real `wheelhil run` (not the fake): the shipped smoke suite passes and a two-run campaign
// over the paper-000 scenario, cut to 1 m, reads the real report's metrics.
TEST_F(CampaignTest, RealRunnerSmokeSuiteAndShortCampaign) {
  SmokeOptions so;
  so.scenarios = FindSmokeScenarios(fs::path(WHEELHIL_SOURCE_DIR) / "scenarios/smoke");
  so.out_dir = dir_.path() / "real_smoke";
  so.runner_exe = WHEELHIL_EXE;
  so.junit = dir_.path() / "real_smoke.xml";
  so.progress = false;
  const auto smoke = RunSmoke(so);
  ASSERT_FALSE(smoke.runs.empty());
  for (const auto& r : smoke.runs) EXPECT_TRUE(r.passed) << r.key << ": " << r.failure;
  EXPECT_TRUE(smoke.passed);
  const std::string smoke_xml = ReadAll(so.junit);
  EXPECT_THAT(smoke_xml, HasSubstr(fmt::format("tests=\"{}\"", smoke.runs.size())));
  if (std::system("command -v xmllint >/dev/null 2>&1") == 0) {
    const std::string cmd = "xmllint --noout --schema " + std::string(WHEELHIL_SOURCE_DIR) +
                            "/tests/data/junit/junit.xsd " + so.junit.string() + " 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << smoke_xml;
  }

  const auto spec = ParseCampaign(
      "base: " + std::string(WHEELHIL_SOURCE_DIR) +
          "/scenarios/paper000_slip.yaml\n"
          "set:\n  motion[1].distance: 1.0\n"
          "parameters: [{path: terrain.random_patches.count, values: [0, 4]}]\n"
          "pass:\n  verdict: false\n  run: [{metric: pose.final_position_error_m, max: 0.25}]\n",
      (dir_.path() / "real.yaml").string());
  auto o = Options("real");
  o.runner_exe = WHEELHIL_EXE;
  const auto out = RunCampaign(spec, o);
  ASSERT_EQ(out.runs.size(), 2u);
  for (const auto& r : out.runs) {
    EXPECT_NE(r.verdict, "error") << r.failure;
    ASSERT_EQ(r.metrics.count("pose.final_position_error_m"), 1u) << r.key;
    EXPECT_NEAR(r.metrics.at("pose.distance_m"), 1.0, 0.1);
    EXPECT_TRUE(r.passed) << r.failure;
  }
}

}  // namespace
}  // namespace wheelhil::emulator::campaign
