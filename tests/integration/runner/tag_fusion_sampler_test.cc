// tag_fusion's random configurations (PPOE paper, exp. II): a configuration is kept only when
// the hand's axis is within max_ee_axis_to_sight_deg of the camera's line of sight, and
// configurations.csv reports the angle (and how obliquely the used tags were seen) per row.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "scenarios/runner/runner.h"
#include "tests/common/test_util.h"

namespace flexbench::scenarios {
namespace {

namespace fs = std::filesystem;

std::vector<std::map<std::string, std::string>> ReadCsv(const fs::path& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  std::vector<std::string> header;
  {
    std::istringstream s(line);
    std::string cell;
    while (std::getline(s, cell, ',')) header.push_back(cell);
  }
  std::vector<std::map<std::string, std::string>> rows;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string cell;
    std::map<std::string, std::string> row;
    for (size_t k = 0; k < header.size() && std::getline(s, cell, ','); ++k) row[header[k]] = cell;
    rows.push_back(row);
  }
  return rows;
}

RunOptions Exp2(const std::string& name, std::vector<std::string> set) {
  RunOptions o;
  o.scenario_path = testing::SourceDir() + "/scenarios/rover_apriltag_exp2.yaml";
  o.out_dir =
      (fs::temp_directory_path() / ("flexbench_" + name + std::to_string(getpid()))).string();
  o.set = {"random_configurations.count=6"};
  o.set.insert(o.set.end(), set.begin(), set.end());
  return o;
}

// The limit holds for every kept configuration, and without it the sampler also keeps hands
// turned across the line of sight (so the limit is what keeps them out, not the joint ranges).
TEST(TagFusionSampler, HandAxisLimitHoldsForEveryConfiguration) {
  double largest_limited = 0.0, largest_free = 0.0;
  for (const auto& [limit, largest] :
       {std::pair<std::string, double*>{"30", &largest_limited}, {"180", &largest_free}}) {
    const RunOptions o =
        Exp2("sampler_" + limit + "_", {"random_configurations.max_ee_axis_to_sight_deg=" + limit,
                                        "random_configurations.count=12"});
    ASSERT_EQ(RunScenario(o), kExitOk);
    const auto rows = ReadCsv(fs::path(o.out_dir) / "configurations.csv");
    ASSERT_FALSE(rows.empty());
    for (const auto& row : rows) {
      const double axis = std::stod(row.at("ee_axis_to_sight_deg"));
      const double view = std::stod(row.at("view_angle_deg"));
      EXPECT_GE(axis, 0.0);
      EXPECT_LE(axis, 180.0);
      // A row scores one configuration that showed at least one tag (min_tags: 1).
      EXPECT_GE(view, 0.0) << row.at("config");
      EXPECT_LE(view, 90.0) << row.at("config");
      *largest = std::max(*largest, axis);
    }
    fs::remove_all(o.out_dir);
  }
  EXPECT_LE(largest_limited, 30.0);
  EXPECT_GT(largest_free, 30.0);
}

TEST(TagFusionSampler, LimitOutsideItsRangeIsBadInputNamingTheKey) {
  for (const std::string bad : {"0", "-5", "181", "nan"}) {
    const RunOptions o =
        Exp2("sampler_bad_", {"random_configurations.max_ee_axis_to_sight_deg=" + bad});
    ::testing::internal::CaptureStderr();
    EXPECT_EQ(RunScenario(o), kExitBadInput) << bad;
    const std::string err = ::testing::internal::GetCapturedStderr();
    EXPECT_NE(err.find("max_ee_axis_to_sight_deg"), std::string::npos) << bad << ": " << err;
    EXPECT_FALSE(fs::exists(o.out_dir)) << bad;
  }
}

}  // namespace
}  // namespace flexbench::scenarios
