// `wheelhil bench`'s lockstep rows over a kernel vcan, through the real executable:
// `wheelhil bench --worker lockstep-vcan` is what the full bench runs for
// lockstep.<paper>.vcan_rtf. With --uml (and no vcan0 on the host) it boots the user-mode-linux
// guest of tests/vcan/uml_run.sh once and runs the three paper scenarios with the reference
// firmware over vcan0 in it (--quick: 1 s of motion each). Each must give a real-time factor;
// a run that fails in the guest gives "unavailable: <its failure>" and fails this test. Skipped
// with uml_run.sh's reason when the guest cannot boot (no user-mode-linux, sanitizer build).
// Never asserts speeds.

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "emulator/bench/bench_report.h"
#include "emulator/bench/bench_runner.h"

namespace wheelhil::emulator::bench {
namespace {

std::string Text(const nlohmann::json* v) { return v ? v->dump() : std::string("(missing)"); }

TEST(BenchLockstepVcan, EveryPaperRunsOverVcanInTheGuest) {
  const WorkerOutcome w =
      RunWorkerProcess({WHEELHIL_EXE, "bench", "--worker", "lockstep-vcan", "--uml", "--quick",
                        "--source-dir", WHEELHIL_SOURCE_DIR},
                       {});
  ASSERT_TRUE(w.problem.empty()) << w.problem;
  const nlohmann::json* env = GetPath(w.report, "lockstep.vcan_environment");
  ASSERT_TRUE(env && env->is_string()) << w.report.dump();
  for (const auto& paper : BenchScenarios()) {
    const nlohmann::json* rtf = GetPath(w.report, "lockstep." + paper + ".vcan_rtf");
    ASSERT_NE(rtf, nullptr) << w.report.dump();
    if (IsUnavailable(*rtf) && rtf->get<std::string>().find("SKIP: ") != std::string::npos) {
      GTEST_SKIP() << rtf->get<std::string>();
    }
    ASSERT_TRUE(rtf->is_number()) << paper << ": " << Text(rtf);
    EXPECT_GT(rtf->get<double>(), 0.0) << paper;
    // --quick cuts the motion phase to 1 s.
    const nlohmann::json* sim = GetPath(w.report, "lockstep." + paper + ".vcan_sim_s");
    ASSERT_TRUE(sim && sim->is_number()) << paper << ": " << Text(sim);
    EXPECT_NEAR(sim->get<double>(), 1.0, 0.05) << paper;
  }
  EXPECT_NE(env->get<std::string>().find("user-mode-linux"), std::string::npos) << *env;
}

TEST(BenchLockstepVcan, WithoutVcanOrUmlTheRowsSayWhy) {
  if (std::filesystem::exists("/sys/class/net/vcan0")) {
    GTEST_SKIP() << "this host has vcan0: the rows are measured on it";
  }
  const WorkerOutcome w = RunWorkerProcess({WHEELHIL_EXE, "bench", "--worker", "lockstep-vcan",
                                            "--quick", "--source-dir", WHEELHIL_SOURCE_DIR},
                                           {});
  ASSERT_TRUE(w.problem.empty()) << w.problem;
  for (const auto& paper : BenchScenarios()) {
    const nlohmann::json* rtf = GetPath(w.report, "lockstep." + paper + ".vcan_rtf");
    ASSERT_TRUE(rtf && IsUnavailable(*rtf)) << paper << ": " << Text(rtf);
    EXPECT_NE(rtf->get<std::string>().find("--uml"), std::string::npos) << *rtf;
  }
  const nlohmann::json* env = GetPath(w.report, "lockstep.vcan_environment");
  ASSERT_TRUE(env && env->is_string());
  EXPECT_EQ(env->get<std::string>(), "none");
}

}  // namespace
}  // namespace wheelhil::emulator::bench
