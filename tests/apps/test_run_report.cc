// run --timings' table (apps/run_report.h): each stage's quantiles, the throughput, the latency and the front
// end over the pose step, from known times.
#include <gtest/gtest.h>

#include <string>
#include <utility>
#include <vector>

#include "apps/run_report.h"

namespace mcslam::apps {
namespace {

Stage Ramp(double first, double step, int n) {
  Stage s;
  for (int i = 0; i < n; ++i) s.Add(first + step * i);
  return s;
}

TEST(StageTable, QuantilesThroughputLatencyAndTheFrontEndOverThePoseStep) {
  // frontend_total 1..100 ms (median 51, p90 91, p99 100), track 10..19.9 (median 15), frame_total 2..200.
  const std::vector<std::pair<std::string, Stage>> stages = {
      {"frontend_total", Ramp(1, 1, 100)}, {"relocalise", Stage{}}, {"track", Ramp(10, 0.1, 100)},
      {"frame_total", Ramp(2, 2, 100)}};
  const std::string table = StageTable(stages, 100, 4.0);
  EXPECT_NE(table.find("frontend_total               100    51.000    91.000   100.000   100.000"), std::string::npos)
      << table;
  EXPECT_NE(table.find("relocalise                     0\n"), std::string::npos) << table;
  EXPECT_NE(table.find("throughput 25.00 frames/s (100 frames in 4.000 s)"), std::string::npos) << table;
  EXPECT_NE(table.find("latency median 102.000 ms, p99 200.000 ms"), std::string::npos) << table;
  EXPECT_NE(table.find("front end / pose step 3.40"), std::string::npos) << table;  // 51 / 15
}

TEST(StageTable, NoRatioWithoutAPoseStep) {
  const std::string table = StageTable({{"frontend_total", Ramp(1, 1, 10)}, {"track", Stage{}}}, 10, 1.0);
  EXPECT_EQ(table.find("front end / pose step"), std::string::npos) << table;
  EXPECT_EQ(table.find("latency"), std::string::npos) << table;
}

TEST(StageJson, QuantilesAreOrderedAndNullWhenTheStageNeverRan) {
  const nlohmann::json j = StageJson(Ramp(1, 1, 100));
  EXPECT_EQ(j["count"], 100);
  EXPECT_EQ(j["median_ms"], 51.0);
  EXPECT_EQ(j["p90_ms"], 91.0);
  EXPECT_EQ(j["p99_ms"], 100.0);
  EXPECT_EQ(j["max_ms"], 100.0);
  EXPECT_DOUBLE_EQ(j["mean_ms"].get<double>(), 50.5);
  const nlohmann::json none = StageJson(Stage{});
  EXPECT_EQ(none["count"], 0);
  EXPECT_TRUE(none["median_ms"].is_null());
}

}  // namespace
}  // namespace mcslam::apps
