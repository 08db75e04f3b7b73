// TUM trajectories: written for the truth and every estimator of a tag-fusion run,
// read back as evo would, and the scenario's own position error recomputed from the files.
#include "scenarios/runner/common/trajectories.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "scenarios/runner/runner.h"
#include "tests/common/test_util.h"

namespace flexbench::scenarios {
namespace {

namespace fs = std::filesystem;

struct Row {
  double t;
  Vec3 p;
  Eigen::Quaterniond q;
};

std::vector<Row> ReadTum(const fs::path& path) {
  std::ifstream in(path);
  std::vector<Row> rows;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    Row r;
    double qx, qy, qz, qw;
    s >> r.t >> r.p.x() >> r.p.y() >> r.p.z() >> qx >> qy >> qz >> qw;
    EXPECT_FALSE(s.fail()) << path << ": " << line;
    r.q = Eigen::Quaterniond(qw, qx, qy, qz);
    EXPECT_NEAR(r.q.norm(), 1.0, 1e-12);
    rows.push_back(r);
  }
  return rows;
}

// summary.json's throughput: every stage timed, and the pipeline's rate is the count
// over the stages' summed time.
void ExpectPipelineTiming(const nlohmann::json& timing, const std::string& unit,
                          const std::vector<std::string>& stages, int count) {
  double ms = 0.0;
  for (const std::string& stage : stages) {
    const std::string key = stage + "_ms_per_" + unit;
    ASSERT_TRUE(timing.contains(key)) << key << " in " << timing.dump();
    EXPECT_GT(timing[key].get<double>(), 0.0) << key;
    ms += timing[key].get<double>();
  }
  const std::string rate = "pipeline_" + unit + "s_per_s";
  ASSERT_TRUE(timing.contains(rate)) << timing.dump();
  EXPECT_NEAR(timing[rate].get<double>(), 1e3 / ms, 1e-9 * timing[rate].get<double>());
  EXPECT_LT(count / timing[rate].get<double>(), timing["total_s"].get<double>());
}

TEST(Trajectories, TumFilesGiveBackTheScenariosPositionError) {
  RunOptions o;
  o.scenario_path = testing::SourceDir() + "/scenarios/rover_apriltag_exp1.yaml";
  o.out_dir = (fs::temp_directory_path() / ("flexbench_tum_" + std::to_string(getpid()))).string();
  ASSERT_EQ(RunScenario(o), kExitOk);
  const auto summary =
      nlohmann::json::parse(testing::ReadFile(fs::path(o.out_dir) / "summary.json"));
  const fs::path dir = fs::path(o.out_dir) / "trajectories" / "base";
  const std::vector<Row> truth = ReadTum(dir / "truth.tum");
  ASSERT_EQ(static_cast<int>(truth.size()), summary["metrics"]["configurations"].get<int>());
  int estimators = 0;
  for (const auto& [name, e] : summary["estimators"].items()) {
    const std::vector<Row> est = ReadTum(dir / (name + ".tum"));
    ASSERT_EQ(est.size(), truth.size()) << name;
    double sum = 0.0;
    for (size_t k = 0; k < est.size(); ++k) {
      EXPECT_EQ(est[k].t, truth[k].t);
      sum += (est[k].p - truth[k].p).norm();
    }
    EXPECT_NEAR(sum / est.size(), e["metrics"]["pos_err_mean_m"].get<double>(), 1e-9) << name;
    // The covariance beside it: a header and one row of timestamp + 21 entries per pose.
    std::ifstream cov(dir / (name + ".cov.csv"));
    std::string line;
    int rows = -1;
    while (std::getline(cov, line)) {
      if (rows >= 0) {
        EXPECT_EQ(std::count(line.begin(), line.end(), ','), 21) << line;
      }
      ++rows;
    }
    EXPECT_EQ(rows, static_cast<int>(truth.size())) << name;
    ++estimators;
  }
  EXPECT_GE(estimators, 2);
  ExpectPipelineTiming(summary["timing"], "frame", {"simulate", "render", "detect", "estimate"},
                       summary["metrics"]["configurations"].get<int>());
  fs::remove_all(o.out_dir);
}

// mismatch_matrix: one folder per effect column, the cell's error from its files.
TEST(Trajectories, MismatchMatrixCellsGiveBackTheirErrors) {
  RunOptions o;
  o.scenario_path = testing::SourceDir() + "/scenarios/mismatch_matrix.yaml";
  o.out_dir =
      (fs::temp_directory_path() / ("flexbench_tum_mm_" + std::to_string(getpid()))).string();
  ASSERT_EQ(RunScenario(o), kExitOk);
  const auto summary =
      nlohmann::json::parse(testing::ReadFile(fs::path(o.out_dir) / "summary.json"));
  int cells = 0;
  for (const auto& [name, e] : summary["estimators"].items()) {
    for (const auto& [column, m] : e["metrics"].items()) {
      if (!m.is_object() || !m.contains("pos_err_mean_m")) continue;
      const fs::path dir = fs::path(o.out_dir) / "trajectories" / "base" / column;
      const std::vector<Row> truth = ReadTum(dir / "truth.tum");
      const std::vector<Row> est = ReadTum(dir / (name + ".tum"));
      ASSERT_EQ(est.size(), truth.size()) << name << " " << column;
      ASSERT_FALSE(est.empty());
      double sum = 0.0;
      for (size_t k = 0; k < est.size(); ++k) sum += (est[k].p - truth[k].p).norm();
      EXPECT_NEAR(sum / est.size(), m["pos_err_mean_m"].get<double>(), 1e-9)
          << name << " " << column;
      ++cells;
    }
  }
  EXPECT_GE(cells, 8);
  fs::remove_all(o.out_dir);
}

// The jsk kinds: a pose per step; pos_err_mean_m counts the steps after the burn-in (set here to
// a value of the test's own, in seconds or in steps).
struct JskCase {
  const char* scenario;
  const char* burn_in_key;
  double burn_in;
};

class JskTrajectories : public ::testing::TestWithParam<JskCase> {};

TEST_P(JskTrajectories, TumFilesGiveBackThePositionErrorAfterTheBurnIn) {
  const JskCase c = GetParam();
  RunOptions o;
  o.scenario_path = testing::SourceDir() + "/scenarios/" + c.scenario + ".yaml";
  o.out_dir = (fs::temp_directory_path() /
               ("flexbench_tum_" + std::string(c.scenario) + std::to_string(getpid())))
                  .string();
  char set[64];
  std::snprintf(set, sizeof(set), "%s=%g", c.burn_in_key, c.burn_in);
  o.set = {set};
  o.quiet = true;
  ASSERT_EQ(RunScenario(o), kExitOk);
  const auto summary =
      nlohmann::json::parse(testing::ReadFile(fs::path(o.out_dir) / "summary.json"));
  const fs::path dir = fs::path(o.out_dir) / "trajectories" / "base";
  const std::vector<Row> truth = ReadTum(dir / "truth.tum");
  const bool in_steps = std::string(c.burn_in_key) == "burn_in_steps";
  int estimators = 0;
  for (const auto& [name, e] : summary["estimators"].items()) {
    const std::vector<Row> est = ReadTum(dir / (name + ".tum"));
    ASSERT_EQ(est.size(), truth.size()) << name;
    double sum = 0.0;
    int n = 0;
    for (size_t k = 0; k < est.size(); ++k) {
      EXPECT_EQ(est[k].t, truth[k].t);
      if (in_steps ? k < c.burn_in : truth[k].t < c.burn_in) continue;
      sum += (est[k].p - truth[k].p).norm();
      ++n;
    }
    ASSERT_GT(n, 0);
    EXPECT_NEAR(sum / n, e["metrics"]["pos_err_mean_m"].get<double>(), 1e-9) << name;
    ++estimators;
  }
  EXPECT_GE(estimators, 4);
  if (std::string(c.scenario) == "jsk_flexible_arm") {
    std::vector<std::string> stages = {"simulate"};
    for (const auto& [name, e] : summary["estimators"].items()) stages.push_back(name);
    ExpectPipelineTiming(summary["timing"], "step", stages,
                         summary["metrics"]["snapshots"].get<int>());
  }
  fs::remove_all(o.out_dir);
}

INSTANTIATE_TEST_SUITE_P(Kinds, JskTrajectories,
                         ::testing::Values(JskCase{"jsk_flexible_arm", "burn_in_s", 1.5},
                                           JskCase{"jsk_direct_fusion", "burn_in_s", 1.5},
                                           JskCase{"jsk_sim_deflection", "burn_in_steps", 7}),
                         [](const ::testing::TestParamInfo<JskCase>& i) {
                           return std::string(i.param.scenario);
                         });

TEST(Trajectories, TumLineIsTimestampPositionQuaternionXyzw) {
  const lie::SE3 T(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()).toRotationMatrix(), Vec3(1, 2, 3));
  std::istringstream s(TumLine(0.5, T));
  double v[8];
  for (double& x : v) s >> x;
  EXPECT_EQ(v[0], 0.5);
  EXPECT_EQ(v[1], 1.0);
  EXPECT_EQ(v[3], 3.0);
  EXPECT_NEAR(v[6], std::sqrt(0.5), 1e-15);  // qz
  EXPECT_NEAR(v[7], std::sqrt(0.5), 1e-15);  // qw last
}

}  // namespace
}  // namespace flexbench::scenarios
