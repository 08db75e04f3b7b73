// Speed of identification: 200 configurations of rover_arm with measured
// end-effector points in 4 sets, 30 candidate effects, two of them in the data (a gear
// compliance at j2, an encoder offset at j3). BM_Identify runs every stage (loads, selection
// cross-validated over the 4 sets, diagnostics, alternatives, equivalence sets, covariance,
// shares); target at most 10 s. BM_IdentifyBicOnly is the same without cross-validation (BIC
// alone), for the ratio. BM_Predict is one augmented forward kinematics.
// Run with --benchmark_repetitions=5 --benchmark_report_aggregates_only=true; quote medians.
#include <benchmark/benchmark.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

#include "scenarios/identify/calibration_data.h"
#include "scenarios/identify/identify.h"
#include "scenarios/identify/measurement_frames.h"
#include "scenarios/identify/parallel.h"
#include "scenarios/runner/runner.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "tests/unit/identify/counting_heap.h"

namespace flexbench::identify {
namespace {

using testing::PeakMemory;

struct Setup {
  sim::MjModelPtr m;
  sim::DeclaredChain chain;
  std::unique_ptr<EffectModel> em;
  DataSet data;
  std::vector<int> candidates;
};

// Filled in place: the effect model keeps a reference to the chain.
void FillRover(Setup& s, int rows) {
  {
    const std::string dir = std::string(FLEXBENCH_SOURCE_DIR) + "/models/";
    s.m = sim::LoadModel(dir + "rover_arm.xml");
    const sim::DeclaredModel d = sim::LoadDeclaredModel(dir + "rover_arm.declared.yaml");
    s.chain = sim::BuildDeclaredChain(s.m.get(), d);
    s.em = std::make_unique<EffectModel>(s.m.get(), s.chain, s.chain.end_effector);
    const std::vector<int> truth = {s.em->FindCandidate("joint_compliance@j2"),
                                    s.em->FindCandidate("joint_offset@j3")};
    const double theta[2] = {-1.2e-3, 0.005};  // a gear of 830 N m/rad (c = -1/k), 0.29 deg
    std::mt19937_64 rng(1);
    std::uniform_real_distribution<double> u(-1.2, 1.2);
    std::normal_distribution<double> n(0.0, 1e-4);
    EffectModel::Workspace ws = s.em->MakeWorkspace();
    s.data.sets = {"s0", "s1", "s2", "s3"};
    for (int r = 0; r < rows; ++r) {
      Observation o;
      o.q = Eigen::VectorXd(s.chain.model.nq());
      for (int k = 0; k < o.q.size(); ++k) o.q[k] = u(rng);
      o.p_base =
          s.em->Predict(o.q, s.em->Loads(o.q), truth, theta, ws) + Vec3(n(rng), n(rng), n(rng));
      o.set = r % 4;
      s.data.rows.push_back(o);
    }
    for (size_t i = 0; i < s.em->candidates().size() && s.candidates.size() < 30; ++i) {
      s.candidates.push_back(static_cast<int>(i));
    }
  }
}

Setup& Rover() {
  static Setup s;
  if (!s.em) FillRover(s, 200);
  return s;
}

void BM_Identify(benchmark::State& state) {
  Setup& s = Rover();
  size_t found = 0;
  IdentifyOptions opt;
  opt.cross_validation = state.range(0) != 0;
  for (auto _ : state) {
    const RowLoads loads = ComputeLoads(*s.em, s.data);
    const IdentifyResult r = Identify(*s.em, s.data, loads, s.candidates, opt);
    found = r.effects.size();
    benchmark::DoNotOptimize(found);
  }
  state.counters["configurations"] = s.data.rows.size();
  state.counters["candidates"] = s.candidates.size();
  state.counters["effects_found"] = found;
}
// Arg 1: cross-validated selection (the default); arg 0: BIC only.
BENCHMARK(BM_Identify)->Arg(1)->Arg(0)->Unit(benchmark::kMillisecond)->Iterations(1);

// What the lateral compliance family costs: identification over every candidate of the rover
// (Arg 1) against the same without lateral_compliance (Arg 0), all stages on; the family's
// columns are analytic (EffectModel::PoseTangents) and its loads come with the joint torques.
void BM_IdentifyLateralFamily(benchmark::State& state) {
  Setup& s = Rover();
  std::vector<int> candidates;
  for (size_t i = 0; i < s.em->candidates().size(); ++i) {
    if (state.range(0) == 0 && s.em->candidates()[i].type == EffectType::kLateralCompliance) {
      continue;
    }
    candidates.push_back(static_cast<int>(i));
  }
  size_t found = 0;
  for (auto _ : state) {
    const RowLoads loads = ComputeLoads(*s.em, s.data);
    const IdentifyResult r = Identify(*s.em, s.data, loads, candidates, IdentifyOptions());
    found = r.effects.size();
    benchmark::DoNotOptimize(found);
  }
  state.counters["candidates"] = candidates.size();
  state.counters["effects_found"] = found;
}
BENCHMARK(BM_IdentifyLateralFamily)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(1);

void BM_Predict(benchmark::State& state) {
  Setup& s = Rover();
  const std::vector<int> active = {s.em->FindCandidate("joint_compliance@j2"),
                                   s.em->FindCandidate("link_bending@j3"),
                                   s.em->FindCandidate("base_compliance@base_plate")};
  const double theta[4] = {1e-3, 1e-4, 1e-4, 1e-4};
  const ConfigLoads loads = s.em->Loads(s.data.rows[0].q);
  EffectModel::Workspace ws = s.em->MakeWorkspace();
  for (auto _ : state) {
    benchmark::DoNotOptimize(s.em->Predict(s.data.rows[0].q, loads, active, theta, ws));
  }
}
BENCHMARK(BM_Predict);

// Reading a point-format CSV of N rows (the file
// is written once, outside the timing). Linear: about 1 us a row.
// Arg 1: a `set` label of its own on every row (labels are looked up once a row).
void ReadPointCsv(benchmark::State& state, bool set_per_row) {
  Setup& s = Rover();
  const int rows = static_cast<int>(state.range(0));
  const std::string path =
      (std::filesystem::temp_directory_path() /
       ("flexbench_bench_points_" + std::to_string(rows) + (set_per_row ? "_sets" : "") + ".csv"))
          .string();
  {
    std::ofstream out(path);
    for (const std::string& j : s.chain.q_joints) out << j << ",";
    out << "x,y,z" << (set_per_row ? ",set" : "") << "\n";
    std::mt19937_64 rng(2);
    std::uniform_real_distribution<double> u(-1.2, 1.2);
    char buf[64];
    for (int r = 0; r < rows; ++r) {
      for (size_t k = 0; k < s.chain.q_joints.size() + 3; ++k) {
        std::snprintf(buf, sizeof(buf), "%.12g%s", u(rng),
                      k + 1 < s.chain.q_joints.size() + 3 ? "," : "");
        out << buf;
      }
      if (set_per_row) out << ",session_" << r;
      out << "\n";
    }
  }
  for (auto _ : state) {
    DataSet d;
    ReadCalibrationCsv(path, s.chain.q_joints, &d);
    benchmark::DoNotOptimize(d.rows.data());
  }
  std::filesystem::remove(path);
  state.SetComplexityN(rows);
}
void BM_ReadPointCsv(benchmark::State& state) { ReadPointCsv(state, false); }
void BM_ReadPointCsvSetPerRow(benchmark::State& state) { ReadPointCsv(state, true); }
BENCHMARK(BM_ReadPointCsv)
    ->RangeMultiplier(10)
    ->Range(100, 10000)
    ->Unit(benchmark::kMillisecond)
    ->Complexity();
BENCHMARK(BM_ReadPointCsvSetPerRow)
    ->RangeMultiplier(10)
    ->Range(100, 10000)
    ->Unit(benchmark::kMillisecond)
    ->Complexity();

// The whole identification on N point rows (rover_arm, 20 candidates): how it scales.
void BM_IdentifyRows(benchmark::State& state) {
  Setup s;
  FillRover(s, static_cast<int>(state.range(0)));
  size_t found = 0;
  for (auto _ : state) {
    const RowLoads loads = ComputeLoads(*s.em, s.data);
    const IdentifyResult r = Identify(*s.em, s.data, loads, s.candidates, IdentifyOptions{});
    found = r.effects.size();
    benchmark::DoNotOptimize(found);
  }
  state.counters["effects_found"] = found;
  state.SetComplexityN(state.range(0));
}
BENCHMARK(BM_IdentifyRows)
    ->Arg(250)
    ->Arg(500)
    ->Arg(1000)
    ->Arg(2000)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->Complexity();

// Identification as the CLI runs it: `flexbench identify` on a point-format CSV of N rows
// (planar3, every candidate, a planted joint offset; the file is written outside the timing):
// the CSV read, the loads and the whole identification, with its peak heap per row. Targets:
// 10,000 rows under 5 s; at most 1 KB a row, and 1,000,000 rows within 2 GB. From 100,000 rows
// on, most rows' loads are computed in every pass (RowLoads) and the fits work on row blocks.
// The figures are in docs/performance.md.
void IdentifyPointCsv(benchmark::State& state, bool geometry) {
  const int rows = static_cast<int>(state.range(0));
  const std::string dir = std::string(FLEXBENCH_SOURCE_DIR) + "/models/";
  const sim::MjModelPtr m = sim::LoadModel(dir + "planar3.xml");
  const sim::DeclaredModel d = sim::LoadDeclaredModel(dir + "planar3.declared.yaml");
  const sim::DeclaredChain chain = sim::BuildDeclaredChain(m.get(), d);
  const EffectModel em(m.get(), chain, chain.end_effector);
  std::vector<int> truth = {em.FindCandidate("joint_offset@joint2")};
  std::vector<double> theta = {0.004};
  if (geometry) {
    // Millimetres and milliradians at two joint origins: the complete-geometry block is kept,
    // so the later stages work beside a dozen fitted unknowns.
    for (const char* name : {"joint_origin@joint2", "joint_origin@joint3"}) {
      truth.push_back(em.FindCandidate(name));
      for (double v : {0.002, -0.0015, 0.001, 0.003, -0.002, 0.0025}) theta.push_back(v);
    }
  }
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("flexbench_bench_identify_" + std::to_string(rows) + ".csv"))
                               .string();
  {
    std::ofstream out(path);
    for (const std::string& j : chain.q_joints) out << j << ",";
    out << "x,y,z,set\n";
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> u(-1.2, 1.2);
    std::normal_distribution<double> n(0.0, 1e-4);
    EffectModel::Workspace ws = em.MakeWorkspace();
    char buf[64];
    for (int r = 0; r < rows; ++r) {
      Eigen::VectorXd q(chain.model.nq());
      for (int k = 0; k < q.size(); ++k) {
        q[k] = u(rng);
        std::snprintf(buf, sizeof(buf), "%.12g,", q[k]);
        out << buf;
      }
      const Vec3 p =
          em.Predict(q, em.Loads(q), truth, theta.data(), ws) + Vec3(n(rng), n(rng), n(rng));
      std::snprintf(buf, sizeof(buf), "%.12g,%.12g,%.12g,s%d\n", p.x(), p.y(), p.z(), r % 4);
      out << buf;
    }
  }
  std::vector<int> candidates(em.candidates().size());
  for (size_t i = 0; i < candidates.size(); ++i) candidates[i] = static_cast<int>(i);
  size_t found = 0;
  double heap = 0.0;
  for (auto _ : state) {
    const PeakMemory peak;
    DataSet data;
    ReadCalibrationCsv(path, chain.q_joints, &data);
    const RowLoads loads = ComputeLoads(em, data);
    IdentifyOptions opt;
    opt.threads = static_cast<int>(state.range(1));
    const IdentifyResult r = Identify(em, data, loads, candidates, opt);
    found = r.effects.size();
    benchmark::DoNotOptimize(found);
    heap = peak.HeapBytes();
  }
  std::filesystem::remove(path);
  state.counters["effects_found"] = found;
  state.counters["candidates"] = candidates.size();
  state.counters["peak_heap_B_per_row"] = heap / rows;
  state.counters["threads"] = PassThreads(rows, static_cast<int>(state.range(1)));
}
void BM_IdentifyPointCsv(benchmark::State& state) { IdentifyPointCsv(state, false); }
// The same rows with joint-origin errors planted too (the memory of a fit with many unknowns).
void BM_IdentifyPointCsvGeometry(benchmark::State& state) { IdentifyPointCsv(state, true); }
// Args: rows, threads of the row passes (1; 0: one per core). Wall time (what a user waits)
// and the whole process's CPU time (all threads), one run each.
void PointCsvRuns(benchmark::internal::Benchmark* b) {
  b->Unit(benchmark::kMillisecond)->Iterations(1)->UseRealTime()->MeasureProcessCPUTime();
}
BENCHMARK(BM_IdentifyPointCsv)
    ->ArgsProduct({{1000, 4000, 10000}, {1, 0}})
    ->Args({100000, 0})
    ->Args({1000000, 0})
    ->Apply(PointCsvRuns);
BENCHMARK(BM_IdentifyPointCsvGeometry)
    ->Args({10000, 0})
    ->Args({100000, 0})
    ->Args({1000000, 0})
    ->Apply(PointCsvRuns);

// The closed loop at real-robot scale: humanoid_upper (19 actuated joints), a tracker of
// unknown pose sees a marker on each hand (unknown offsets on their links) over 300 random
// postures, 0.2 mm noise per axis: 600 rows. The truth (the effect model itself; the scenarios
// check physics-made data) has a joint-origin error at every joint (0.5-2 mm, 0.1-0.5 deg,
// drawn from a fixed seed) and gear compliance at both shoulders' pitch and both elbows, so the
// data warrant 30 or more effects. Every candidate of the model is offered, as the CLI does.
struct Humanoid {
  sim::MjModelPtr m;
  sim::DeclaredChain chain;
  std::unique_ptr<EffectModel> em;
  DataSet data;
  RowLoads loads;
  std::vector<int> candidates;
  int truth_effects = 0;
};

// The truth's active effects and their parameters: joint origins everywhere, gear compliance
// at the shoulders' pitch and the elbows.
void HumanoidTruth(const EffectModel& em, std::vector<int>* active, std::vector<double>* theta) {
  std::mt19937_64 rng(34);
  std::uniform_real_distribution<double> mm(0.5e-3, 2e-3), deg(0.1, 0.5), sign(-1.0, 1.0);
  const auto draw = [&](double mag) { return sign(rng) < 0 ? -mag : mag; };
  for (size_t c = 0; c < em.candidates().size(); ++c) {
    if (em.candidates()[c].type != EffectType::kJointOrigin) continue;
    active->push_back(static_cast<int>(c));
    Vec3 t(sign(rng), sign(rng), sign(rng)), w(sign(rng), sign(rng), sign(rng));
    t *= draw(mm(rng)) / t.norm();
    w *= draw(deg(rng)) * M_PI / 180.0 / w.norm();
    for (int k = 0; k < 3; ++k) theta->push_back(t[k]);
    for (int k = 0; k < 3; ++k) theta->push_back(w[k]);
  }
  for (const char* j : {"shoulder_pitch", "l_shoulder_pitch", "elbow", "l_elbow"}) {
    active->push_back(em.FindCandidate(std::string("joint_compliance@") + j));
    theta->push_back(-1e-3);  // a gear of 1000 N m/rad
  }
}

Humanoid& HumanoidSetup() {
  static Humanoid h;
  if (h.em) return h;
  const std::string dir = std::string(FLEXBENCH_SOURCE_DIR) + "/models/";
  h.m = sim::LoadModel(dir + "humanoid_upper.xml");
  const sim::DeclaredModel d = sim::LoadDeclaredModel(dir + "humanoid_upper.declared.yaml");
  h.chain = sim::BuildDeclaredChain(h.m.get(), d);
  const std::vector<kinematics::FrameId> markers = {h.chain.ObservedFrame("right_marker"),
                                                    h.chain.ObservedFrame("left_marker")};
  h.em = std::make_unique<EffectModel>(h.m.get(), h.chain, h.chain.end_effector, "", markers,
                                       /*gravity_tilt=*/true);
  std::vector<int> truth;
  std::vector<double> theta;
  HumanoidTruth(*h.em, &truth, &theta);
  h.truth_effects = static_cast<int>(truth.size());
  h.data.points = {d.end_effector, "right_marker", "left_marker"};
  h.data.offset_unknown = {0, 1, 1};
  MeasurementFrame tracker;
  tracker.name = "tracker";
  h.data.frames = {tracker};
  h.data.sets = {"calibration"};
  const lie::SE3 T_base_tracker(Eigen::AngleAxisd(M_PI + 0.05, Vec3::UnitZ()).toRotationMatrix() *
                                    Eigen::AngleAxisd(0.03, Vec3::UnitX()).toRotationMatrix(),
                                Vec3(2.5, 0.04, 1.6));
  const Vec3 d_true[3] = {Vec3::Zero(), Vec3(0.012, -0.014, 0.008), Vec3(-0.007, 0.009, 0.004)};
  std::mt19937_64 rng(35);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, 2e-4);
  const auto range = [](const std::string& j) -> std::pair<double, double> {
    const std::string b = j.rfind("l_", 0) == 0 ? j.substr(2) : j;
    if (b == "shoulder_pitch") return {-110, 0};
    if (b == "shoulder_roll")
      return j == b ? std::make_pair(-45.0, 10.0) : std::make_pair(-10.0, 45.0);
    if (b == "shoulder_yaw") return {-45, 45};
    if (b == "elbow") return {-100, 0};
    if (b == "forearm_roll") return {-60, 60};
    return {-30, 30};
  };
  EffectModel::Workspace ws = h.em->MakeWorkspace();
  for (int posture = 0; posture < 300; ++posture) {
    Eigen::VectorXd q(h.chain.model.nq());
    for (int k = 0; k < q.size(); ++k) {
      const auto [lo, hi] = range(h.chain.q_joints[k]);
      q[k] = (lo + (hi - lo) * u(rng)) * M_PI / 180.0;
    }
    const ConfigLoads L = h.em->Loads(q);
    for (int point = 1; point <= 2; ++point) {
      Observation o;
      o.q = q;
      o.frame = 0;
      o.point = point;
      const Vec3 p_base = h.em->PredictPose(q, L, truth, theta.data(), ws, point) * d_true[point];
      o.p_frame = T_base_tracker.Inverse() * p_base + Vec3(noise(rng), noise(rng), noise(rng));
      h.data.rows.push_back(o);
    }
  }
  h.loads = ComputeLoads(*h.em, h.data);
  RegisterFrames(*h.em, h.loads, &h.data);
  for (size_t c = 0; c < h.em->candidates().size(); ++c)
    h.candidates.push_back(static_cast<int>(c));
  return h;
}

// Arg 0: cross-validation (1, the default) or not (0); arg 1: max_effects (-1: no cap).
void BM_IdentifyHumanoid(benchmark::State& state) {
  Humanoid& h = HumanoidSetup();
  IdentifyOptions opt;
  opt.cross_validation = state.range(0) != 0;
  opt.max_effects = static_cast<int>(state.range(1));
  opt.point_std_m = 2e-4;
  opt.threads = 2;
  size_t found = 0;
  double noise_ratio = 0.0;
  int alternatives = 0;
  std::string stopped;
  for (auto _ : state) {
    const IdentifyResult r = Identify(*h.em, h.data, h.loads, h.candidates, opt);
    found = r.after.active.size();
    noise_ratio = NoiseRatio(r.after);
    alternatives = static_cast<int>(r.alternatives.size());
    stopped = r.stopped_by;
  }
  state.counters["rows"] = h.data.rows.size();
  state.counters["candidates"] = h.candidates.size();
  state.counters["truth_effects"] = h.truth_effects;
  state.counters["effects_found"] = found;
  state.counters["alternatives"] = alternatives;
  state.counters["rms_over_noise"] = noise_ratio;
  state.SetLabel("stopped_by " + stopped);
}
BENCHMARK(BM_IdentifyHumanoid)
    ->ArgNames({"cv", "max_effects"})
    ->Args({1, 8})
    ->Args({0, 8})
    ->Args({1, -1})
    ->Args({0, -1})
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

// Point rows at scale (rover_arm, 30 candidates, two effects in the data): the whole
// identification's time and its peak heap above what the data itself holds, per row.
void BM_IdentifyRowsMemory(benchmark::State& state) {
  const int rows = static_cast<int>(state.range(0));
  double heap = 0.0, rss = 0.0, data_bytes = 0.0;
  size_t found = 0;
  for (auto _ : state) {
    state.PauseTiming();
    const PeakMemory all;
    {
      Setup s;
      FillRover(s, rows);
      data_bytes = all.HeapBytes();
      state.ResumeTiming();
      const RowLoads loads = ComputeLoads(*s.em, s.data);
      IdentifyOptions opt;
      opt.threads = static_cast<int>(state.range(1));
      const IdentifyResult r = Identify(*s.em, s.data, loads, s.candidates, opt);
      found = r.effects.size();
      state.PauseTiming();
    }
    heap = all.HeapBytes();
    rss = all.RssBytes();
    state.ResumeTiming();
  }
  state.counters["effects_found"] = found;
  state.counters["peak_heap_B_per_row"] = heap / rows;
  state.counters["data_B_per_row"] = data_bytes / rows;
  state.counters["maxrss_growth_B_per_row"] = rss / rows;
}
// Args: rows, threads.
BENCHMARK(BM_IdentifyRowsMemory)
    ->ArgNames({"rows", "threads"})
    ->ArgsProduct({{1000, 10000, 100000}, {1, 2}})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

// The closed loop's DLR-class problem as a user runs it (closed_loop_humanoid_dlr: MuJoCo
// physics, 17 read joints and a coupled one, 600 calibration rows, an unknown tracker pose and
// two unknown marker offsets, 227 candidates): `flexbench identify` on the scenario's exported
// CSVs with every setting at its default (the worked example of docs/identification.md), outputs
// included. The CSVs are made once, outside the timing, by the scenario with max_effects 0 and no
// gates.
const std::string& DlrData() {
  static const std::string dir = [] {
    const std::string out =
        (std::filesystem::temp_directory_path() / "flexbench_bench_dlr_data").string();
    scenarios::RunOptions run;
    run.scenario_path =
        std::string(FLEXBENCH_SOURCE_DIR) + "/scenarios/closed_loop_humanoid_dlr.yaml";
    run.out_dir = out;
    run.force = true;
    run.quiet = true;
    run.set = {"max_effects=0", "gates=[]"};  // data only: no gate to fail
    if (scenarios::RunScenario(run) != scenarios::kExitOk) std::abort();
    return out;
  }();
  return dir;
}

// Arg 0: cross-validation (1, the default: alternatives and every stage) or not (0).
void BM_IdentifyDlr(benchmark::State& state) {
  scenarios::IdentifyCliOptions o;
  o.declared = std::string(FLEXBENCH_SOURCE_DIR) + "/models/humanoid_upper_torso.declared.yaml";
  o.calibration_csv = DlrData() + "/calibration_data.csv";
  o.validation_csv = DlrData() + "/validation_data.csv";
  o.frames = {"tracker"};
  o.markers = o.unknown_marker_offsets = {"right_marker", "left_marker"};
  o.point_std_m = 2e-4;
  o.no_cross_validation = state.range(0) == 0;
  o.out_dir = (std::filesystem::temp_directory_path() / "flexbench_bench_dlr_identify").string();
  o.force = true;
  o.quiet = true;
  for (auto _ : state) {
    if (scenarios::IdentifyCommand(o) != scenarios::kExitOk) state.SkipWithError("identify failed");
  }
}
BENCHMARK(BM_IdentifyDlr)
    ->ArgNames({"cv"})
    ->Arg(1)
    ->Arg(0)
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->Repetitions(3)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

}  // namespace
}  // namespace flexbench::identify

BENCHMARK_MAIN();
