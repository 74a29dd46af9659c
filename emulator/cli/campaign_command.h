#pragma once
/// `wheelhil campaign FILE [--jobs N] [--db results.sqlite] [--shard K/N] [--junit out.xml]
/// [--out DIR] [--runner EXE]`, `wheelhil campaign merge --out merged.sqlite SHARD.sqlite...`
/// and `wheelhil smoke [--junit out.xml] [--firmware CMD] [--scenarios DIR|LIST] [--jobs N]`.
/// See docs/campaigns.md and docs/ci.md. Exit codes: 0 campaign/smoke passed (a shard: all its
/// runs stored), 1 failed or incomplete, 2 usage or input error. Thread-compatible.

#include <CLI/CLI.hpp>

#include <optional>
#include <string>
#include <vector>

namespace wheelhil::emulator {

class CampaignCommand {
 public:
  /// Adds the `campaign` and `smoke` subcommands to `app` (call before parsing).
  explicit CampaignCommand(CLI::App& app);
  /// After parsing: the exit code when one of these subcommands ran, else nullopt.
  std::optional<int> Run();

 private:
  int RunCampaign();
  int RunMerge();
  int RunSmoke();

  CLI::App* campaign_ = nullptr;
  CLI::App* merge_ = nullptr;
  CLI::App* smoke_ = nullptr;
  std::string file_;
  int jobs_ = 1;
  std::string db_;
  std::string shard_ = "0/1";
  std::string junit_;
  std::string out_;
  std::string runner_;
  bool quiet_ = false;
  bool no_html_ = false;
  std::string merge_out_;
  std::vector<std::string> merge_inputs_;
  std::string smoke_junit_;
  std::string smoke_firmware_;
  std::string smoke_scenarios_;
  std::string smoke_out_ = "smoke";
  std::string smoke_runner_;
  int smoke_jobs_ = 2;
  double smoke_timeout_s_ = 60;
};

}  // namespace wheelhil::emulator
