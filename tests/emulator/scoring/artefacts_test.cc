// HtmlReport (emulator/scoring/artefacts.h): every metric of report["metrics"] becomes one table
// row, in its stream's table, rounded with its unit. Regression for the `wheelhil run` SIGSEGV:
// the metrics loop iterated items() of the temporary returned by report.value(...), i.e. a
// destroyed std::map (ASan: heap-use-after-free). Also the metric formatter and axis ticks
// (emulator/scoring/metric_format.h) and the shaded bands of SvgPlot.

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "emulator/scoring/artefacts.h"
#include "emulator/scoring/metric_format.h"
#include "tests/emulator/scoring/text_checks.h"

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
      const std::string row = fmt::format("<tr><td>metric{:02}</td><td title=\"{}\">{}</td></tr>",
                                          k, s * 100 + k, s * 100 + k);
      const auto first = html.find(row);
      ASSERT_NE(first, std::string::npos) << row;
      EXPECT_EQ(html.find(row, first + 1), std::string::npos) << row;
      // In its stream's table: the nearest heading before it.
      EXPECT_EQ(html.rfind("<h3>", first), html.find(fmt::format("<h3>stream{:02}</h3>", s)))
          << row;
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

TEST(MetricFormat, ValuesAreRoundedToTheirMeaningWithTheUnitOfTheirName) {
  EXPECT_EQ(FormatMetricValue("final_position_error_m", 0.0072318748854), "7.23 mm");
  EXPECT_EQ(FormatMetricValue("rmse_m", 0.0963683135199863), "96.4 mm");
  EXPECT_EQ(FormatMetricValue("distance_m", 1.9729541473609729), "1.97 m");
  EXPECT_EQ(FormatMetricValue("distance_m", 10.004), "10.0 m");
  EXPECT_EQ(FormatMetricValue("final_heading_error_rad", 0.007759740077448729), "7.76 mrad");
  EXPECT_EQ(FormatMetricValue("rotation_rad", 0.16381107673946183), "0.164 rad");
  EXPECT_EQ(FormatMetricValue("velocity_rmse_m_s", 0.020084243271910898), "20.1 mm/s");
  EXPECT_EQ(FormatMetricValue("speed_m_s", 0.25), "0.250 m/s");
  EXPECT_EQ(FormatMetricValue("omega_rmse_rad_s", 0.0123), "12.3 mrad/s");
  EXPECT_EQ(FormatMetricValue("max_queue_delay_s", 0.001652), "1.65 ms");
  EXPECT_EQ(FormatMetricValue("load", 0.033644626125384734), "3.36 %");
  EXPECT_EQ(FormatMetricValue("final_position_error_pct_of_distance", 0.3665505807667779),
            "0.367 %");
  EXPECT_EQ(FormatMetricValue("uncorrected_over_corrected", 14.171617647137815), "14.2\u00d7");
  EXPECT_EQ(FormatMetricValue("samples", 39), "39");
  EXPECT_EQ(FormatMetricValue("corrected_below_uncorrected", true), "yes");
  EXPECT_EQ(FormatMetricValue("min_m", 0.0), "0 m");
  EXPECT_EQ(FormatMetricValue("x_m", -0.0005), "-0.500 mm");
}

TEST(MetricFormat, TicksAreOneTwoOrFiveTimesAPowerOfTen) {
  const AxisTicks a = NiceTicks(-8.003e-10, 1.0);
  EXPECT_DOUBLE_EQ(a.step, 0.2);
  EXPECT_NEAR(a.first, 0.0, 1e-12);
  EXPECT_EQ(a.count, 6);  // 0, 0.2, ..., 1.0
  EXPECT_EQ(a.decimals, 1);
  const AxisTicks b = NiceTicks(-6.95e-05, 0.0131);
  EXPECT_DOUBLE_EQ(b.step, 0.002);
  EXPECT_EQ(b.decimals, 3);
  EXPECT_NEAR(b.first, 0.0, 1e-12);
  const AxisTicks c = NiceTicks(0, 43);
  EXPECT_DOUBLE_EQ(c.step, 10);
  EXPECT_EQ(c.count, 5);
  EXPECT_EQ(c.decimals, 0);
  const AxisTicks d = NiceTicks(2, 2);  // degenerate: one tick, no division by zero
  EXPECT_EQ(d.count, 1);
}

TEST(ScenarioArtefacts, PlotsHaveRoundTicksShadedBandsAndEqualAxesWhenAsked) {
  Series s{"truth", "#000", {0.0, 10.0}, {0.0, 0.96}};
  const std::string svg = SvgPlot("t", "x [m]", "y [m]", {s}, {{2.0, 3.5, "slip", "#f00"}});
  EXPECT_NE(svg.find(">0.2</text>"), std::string::npos) << svg;  // y ticks 0, 0.2, ... 1.0
  EXPECT_NE(svg.find(">10</text>"), std::string::npos);
  EXPECT_EQ(testing::FindExponent(svg), std::string::npos) << svg;
  EXPECT_NE(svg.find("class=\"band\""), std::string::npos);
  EXPECT_NE(svg.find(">slip</text>"), std::string::npos);  // its legend entry
  // Equal axes: 10 m across 550 px, so the 0.96 m drift spans about 53 px, not the full height.
  const std::string eq = SvgPlot("t", "x [m]", "y [m]", {s}, {}, true);
  EXPECT_EQ(eq.find(">0.2</text>"), std::string::npos) << eq;
}

}  // namespace
}  // namespace wheelhil::emulator::scoring
