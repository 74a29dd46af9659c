// HtmlReport (emulator/scoring/artefacts.h): every metric of report["metrics"] becomes one table
// row. Regression for the `wheelhil run` SIGSEGV: the metrics loop iterated items() of the
// temporary returned by report.value(...), i.e. a destroyed std::map (ASan: heap-use-after-free).

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "emulator/scoring/artefacts.h"

namespace wheelhil::emulator::scoring {
namespace {

nlohmann::json ReportWithMetrics(int streams, int keys) {
  nlohmann::json report;
  report["scenario"] = "artefacts_test";
  report["seed"] = 7;
  report["sim_time_s"] = 1.5;
  report["verdict"] = "pass";
  report["expectations"] = nlohmann::json::array(
      {{{"text", "pose.ape_rmse_m < 0.1"}, {"value", 0.05}, {"passed", true}}});
  nlohmann::json metrics = nlohmann::json::object();
  for (int s = 0; s < streams; ++s) {
    for (int k = 0; k < keys; ++k) {
      metrics[fmt::format("stream{:02}", s)][fmt::format("metric{:02}", k)] = s * 100 + k;
    }
  }
  metrics["not_an_object"] = 3;  // skipped: only objects hold metrics
  report["metrics"] = metrics;
  return report;
}

TEST(ScenarioArtefacts, HtmlReportListsEveryMetricOnce) {
  const nlohmann::json report = ReportWithMetrics(12, 9);
  const std::string html = HtmlReport(report, {"<svg id=\"p\"></svg>"});
  for (int s = 0; s < 12; ++s) {
    for (int k = 0; k < 9; ++k) {
      const std::string row = fmt::format(
          "<tr><td>stream{:02}</td><td>metric{:02}</td><td>{}</td></tr>", s, k, s * 100 + k);
      const auto first = html.find(row);
      ASSERT_NE(first, std::string::npos) << row;
      EXPECT_EQ(html.find(row, first + 1), std::string::npos) << row;
    }
  }
  EXPECT_EQ(html.find("not_an_object"), std::string::npos);
  EXPECT_NE(html.find("<div><svg id=\"p\"></svg></div>"), std::string::npos);
  EXPECT_NE(html.find("pose.ape_rmse_m &lt; 0.1"), std::string::npos);
}

TEST(ScenarioArtefacts, HtmlReportWithoutMetricsHasAnEmptyTable) {
  nlohmann::json report = ReportWithMetrics(0, 0);
  report.erase("metrics");
  const std::string html = HtmlReport(report, {});
  EXPECT_NE(html.find("<h2>Metrics</h2>"), std::string::npos);
  EXPECT_EQ(html.find("<td>stream"), std::string::npos);
  EXPECT_NE(html.find("</html>"), std::string::npos);
}

}  // namespace
}  // namespace wheelhil::emulator::scoring
