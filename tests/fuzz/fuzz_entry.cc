#include "tests/fuzz/fuzz_entry.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <stdexcept>

#include "estimators/error.h"
#include "scenarios/identify/calibration_data.h"
#include "scenarios/runner/gates.h"
#include "scenarios/runner/report.h"
#include "scenarios/runner/runner.h"
#include "scenarios/sweep/sweep_file.h"
#include "sim/config.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "sim/recorded_log.h"

namespace fs = std::filesystem;

namespace flexbench::fuzz {
namespace {

std::string g_work_dir;

void RemoveWorkDir() {
  std::error_code ec;
  if (!g_work_dir.empty()) fs::remove_all(g_work_dir, ec);
}

void MakeWorkDir() {
  const char* tmp = std::getenv("TMPDIR");
  std::string pattern = std::string(tmp && *tmp ? tmp : "/tmp") + "/flexbench-fuzz-XXXXXX";
  if (!mkdtemp(pattern.data())) throw std::runtime_error("fuzz: cannot create " + pattern);
  g_work_dir = pattern;
  std::atexit(RemoveWorkDir);
  const fs::path w(g_work_dir);
  for (const char* d : {"scenarios", "declared", "calibration", "mukca/front", "gates", "mjcf",
                        "repo/sweeps", "set", "report/run", "report/sweep"}) {
    fs::create_directories(w / d);
  }
  // Scenario files name their models as ../models/<file>, declared files as <file> (links to
  // the repository's models; the declared reader checks that the file exists).
  const fs::path models = fs::path(FLEXBENCH_SOURCE_DIR) / "models";
  fs::create_directory_symlink(models, w / "models");
  for (const fs::directory_entry& e : fs::directory_iterator(models)) {
    fs::create_symlink(e.path(), w / "declared" / e.path().filename());
  }
  // The sweep target's scenarios: links to the repository's scenario files (read only; their
  // ../models/ is the link above), beside the folder that holds the sweep file.
  const fs::path scenarios = fs::path(FLEXBENCH_SOURCE_DIR) / "scenarios";
  for (const fs::directory_entry& e : fs::directory_iterator(scenarios)) {
    if (e.is_regular_file() && e.path().extension() == ".yaml") {
      fs::create_symlink(e.path(), w / "repo" / e.path().filename());
    }
  }
  // The --set target's scenario: a copy, so no override can reach the repository's file.
  fs::copy_file(scenarios / "smoke.yaml", w / "set" / "base.yaml");
}

// Writes `size` bytes to `path` (replacing it); returns the path.
std::string WriteFile(const fs::path& path, const std::uint8_t* data, std::size_t size) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  f.close();
  if (!f) throw std::runtime_error("fuzz: cannot write " + path.string());
  return path.string();
}

fs::path Work(const char* relative) { return fs::path(WorkDir()) / relative; }

// Runs `body`; an InputError becomes its message, everything else escapes.
template <class F>
std::optional<std::string> Guard(F&& body) {
  try {
    body();
  } catch (const InputError& e) {
    return std::string(e.what());
  }
  return std::nullopt;
}

// The fixed MJCFs of the declared-model target, loaded once, by file name.
const sim::MjModelPtr& FixedModel(const std::string& model_path) {
  static const std::map<std::string, sim::MjModelPtr> models = [] {
    std::map<std::string, sim::MjModelPtr> m;
    for (const char* name : {"planar3.xml", "jsk_arm.xml", "rover_arm.xml", "humanoid_upper.xml"}) {
      m.emplace(name, sim::LoadModel(std::string(FLEXBENCH_SOURCE_DIR) + "/models/" + name));
    }
    return m;
  }();
  const auto it = models.find(fs::path(model_path).filename().string());
  return it != models.end() ? it->second : models.at("planar3.xml");
}

}  // namespace

void Init() {
  static std::once_flag once;
  std::call_once(once, [] {
    sim::InstallMujocoHandlers();
    MakeWorkDir();
  });
}

const std::string& WorkDir() {
  Init();
  return g_work_dir;
}

std::optional<std::string> Scenario(const std::uint8_t* data, std::size_t size) {
  const std::string path = WriteFile(Work("scenarios/fuzz.yaml"), data, size);
  return Guard([&] { scenarios::CheckScenario(path, {}); });
}

std::optional<std::string> DeclaredModel(const std::uint8_t* data, std::size_t size) {
  const std::string path = WriteFile(Work("declared/fuzz.declared.yaml"), data, size);
  return Guard([&] {
    const sim::DeclaredModel declared = sim::LoadDeclaredModel(path);
    // With the couplings resolved (what identification builds), so `coupled:` is covered too.
    sim::BuildDeclaredChain(FixedModel(declared.model_path).get(), declared,
                            /*with_couplings=*/true);
  });
}

std::optional<std::string> CalibrationCsv(const std::uint8_t* data, std::size_t size) {
  const std::string path = WriteFile(Work("calibration/data.csv"), data, size);
  return Guard([&] {
    identify::DataSet d;
    d.camera.present = true;
    d.camera.intrinsics.fx = d.camera.intrinsics.fy = 500.0;
    d.camera.intrinsics.cx = 320.0;
    d.camera.intrinsics.cy = 240.0;
    identify::ReadCalibrationCsv(path, {"j1", "j2"}, &d);
  });
}

std::optional<std::string> Mukca(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  std::string hole0 = text, hole1 = text;
  const std::string line = "----\n";
  size_t cut = text.rfind(line, 0) == 0 ? 0 : text.find("\n" + line);
  if (cut != std::string::npos) {
    if (cut > 0) ++cut;  // keep hole_0's last newline
    hole0 = text.substr(0, cut);
    hole1 = text.substr(cut + line.size());
  }
  const fs::path dir = Work("mukca/front");
  auto bytes = [](const std::string& s) { return reinterpret_cast<const std::uint8_t*>(s.data()); };
  WriteFile(dir / "hole_0.csv", bytes(hole0), hole0.size());
  WriteFile(dir / "hole_1.csv", bytes(hole1), hole1.size());
  return Guard([&] {
    identify::DataSet d;
    identify::ReadMukcaPlacement(dir.string(), "front", 7, 0.05, &d);
  });
}

std::optional<std::string> Gates(const std::uint8_t* data, std::size_t size) {
  const std::string path = WriteFile(Work("gates/gates.yaml"), data, size);
  return Guard([&] {
    const ConfigNode root = ConfigNode::LoadFile(path);
    const std::vector<scenarios::GateSpec> gates = scenarios::ParseGates(root);
    root.CheckNoUnknownKeys();
    static const scenarios::Json summary = scenarios::Json::parse(R"({
      "scenario": "fuzz", "metrics": {"detections": 1, "corner_rmse_px": 0.25, "ok": true,
                                      "none": null, "text": "x"},
      "estimators": {"ppoe_ekf": {"metrics": {"lateral_err_mean_m": 0.001}},
                     "naive_ekf": {"metrics": {"lateral_err_mean_m": 0.002}}}})");
    bool all_passed = false;
    scenarios::EvaluateGates(gates, summary, &all_passed);
    scenarios::CheckGateMetricsExist(gates, summary);
  });
}

std::optional<std::string> Mjcf(const std::uint8_t* data, std::size_t size) {
  const std::string path = WriteFile(Work("mjcf/model.xml"), data, size);
  return Guard([&] { sim::LoadModel(path); });
}

std::optional<std::string> Sweep(const std::uint8_t* data, std::size_t size) {
  const std::string path = WriteFile(Work("repo/sweeps/fuzz.yaml"), data, size);
  return Guard([&] {
    const scenarios::sweep::SweepSpec spec = scenarios::sweep::LoadSweep(path);
    const std::vector<scenarios::sweep::SweepPoint> points = scenarios::sweep::ExpandPoints(spec);
    scenarios::sweep::ExpandRuns(spec, points);
    // `flexbench sweep` configures every point before any run; a few points reach every path
    // of the overrides without making one input cost seconds.
    constexpr size_t kCheckedPoints = 3;
    for (size_t i = 0; i < points.size() && i < kCheckedPoints; ++i) {
      std::vector<std::string> set = spec.set;
      set.insert(set.end(), points[i].set.begin(), points[i].set.end());
      try {
        scenarios::CheckScenario(spec.scenario, set);
      } catch (const InputError& e) {
        // As `flexbench sweep` reports it: the sweep file and the point.
        throw InputError(path + ": point '" + points[i].name + "': " + e.what());
      }
    }
  });
}

std::optional<std::string> SetOverride(const std::uint8_t* data, std::size_t size) {
  std::vector<std::string> args(1);
  for (std::size_t i = 0; i < size; ++i) {
    if (data[i] == 0) {
      args.emplace_back();
    } else {
      args.back() += static_cast<char>(data[i]);
    }
  }
  const std::string base = Work("set/base.yaml").string();
  return Guard([&] { scenarios::CheckScenario(base, args); });
}

std::optional<std::string> Report(const std::uint8_t* data, std::size_t size) {
  std::optional<std::string> error;
  for (const char* file : {"report/run/summary.json", "report/sweep/aggregate.json"}) {
    const fs::path path = Work(file);
    WriteFile(path, data, size);
    // Both folders are rendered even when the first is refused; the messages are joined.
    if (std::optional<std::string> e = Guard([&] { scenarios::WriteReport(path.parent_path()); })) {
      error = error ? *error + " | " + *e : *e;
    }
    std::error_code ec;
    fs::remove(path.parent_path() / "report.html", ec);  // the next input sees the same folder
  }
  return error;
}

std::optional<std::string> RecordedLog(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  constexpr int kParts = 6;
  std::vector<std::string> parts(kParts);
  size_t part = 0, begin = 0;
  while (part < kParts) {
    const size_t cut = text.find("\n----\n", begin);
    if (cut == std::string::npos || part == kParts - 1) {
      parts[part] = text.substr(begin);
      break;
    }
    parts[part++] = text.substr(begin, cut + 1 - begin);
    begin = cut + 6;
  }
  const fs::path dir = Work("log");
  fs::remove_all(dir);
  fs::create_directories(dir);
  const char* names[kParts] = {"joints.csv", "imu.csv",          "truth.tum",
                               "tags.csv",   "orientations.csv", "positions.csv"};
  for (int i = 0; i < kParts; ++i) {
    WriteFile(dir / names[i], reinterpret_cast<const std::uint8_t*>(parts[i].data()),
              parts[i].size());
  }
  // A fourth part is tags.csv, seen by one camera, of two tags (one by its size, one by its
  // corners).
  const std::string yaml =
      std::string(
          "declared: a.declared.yaml\njoints: {file: joints.csv, clock_offset_s: 0.1}\n"
          "imu: {file: imu.csv, sensors: {imu2: {frame: f2}, imu3: {frame: f3, "
          "initial_wxyz: [1, 0, 0, 0]}}}\ntruth: {file: truth.tum, frame: ee}\n") +
      (parts[3].empty()
           ? ""
           : "cameras: {cam0: {frame: c, fx: 500, fy: 500, cx: 320, cy: 240, width: 640, "
             "height: 480}}\ntags: {file: tags.csv, pixel_std_px: 0.5, ids: {20: {frame: t, "
             "size_m: 0.04}, 3: {frame: u, corners_m: [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, "
             "0]]}}}\n") +
      // A fifth and sixth part: orientations.csv and positions.csv.
      (parts[4].empty() ? "" : "orientations: {file: orientations.csv, clock_offset_s: 0.2}\n") +
      (parts[5].empty() ? "" : "positions: {file: positions.csv}\n");
  WriteFile(dir / "log.yaml", reinterpret_cast<const std::uint8_t*>(yaml.data()), yaml.size());
  return Guard([&] {
    const sim::RecordedLog log = sim::ReadRecordedLog(dir.string());
    lie::SE3 T;
    for (double t : log.joint_t) sim::TruthAt(log, t, &T);
    std::vector<int> column(log.joints.size());
    for (size_t k = 0; k < column.size(); ++k) column[k] = static_cast<int>(k);
    Eigen::VectorXd q;
    for (const sim::LogTagRow& r : log.tag_rows) sim::JointsAt(log, column, r.t, &q);
  });
}

const std::vector<Target>& Targets() {
  static const std::vector<Target> targets = {
      {"scenario", Scenario},
      {"declared_model", DeclaredModel},
      {"calibration_csv", CalibrationCsv},
      {"mukca", Mukca},
      {"gates", Gates},
      {"mjcf", Mjcf},
      {"sweep", Sweep},
      {"set", SetOverride, "--set"},
      {"report", Report},
      {"recorded_log", RecordedLog},
  };
  return targets;
}

}  // namespace flexbench::fuzz
