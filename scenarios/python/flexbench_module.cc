// The `flexbench` Python module (pybind11): declared models and their probabilistic forward
// kinematics, the estimators by registry name, and the runner's `run` and `identify` commands.
// numpy in and out: joint vectors are read in place when they are contiguous float64 arrays,
// results are written straight into new numpy arrays (row-major 4x4 poses, 6x6 covariances in
// the local tangent space, [rho; theta] order).
//
// Errors: everything the command line would report as bad input (InputError, exit code 2)
// raises ValueError with the text the CLI prints after "flexbench: error: " (the runner's own
// ReportError formats it); wrong array shapes and dtypes raise ValueError too. Other C++
// exceptions become RuntimeError; none reaches the interpreter as a crash. A fatal MuJoCo error
// is an exception too (sim::InstallMujocoHandlers), so it unwinds to here as ValueError.
//
// Threads: what touches MuJoCo's hooks, the GL context or std::cerr (run_scenario, identify,
// DeclaredModel.load) runs one call at a time under a process-wide lock; see LockProcess.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <Eigen/Eigenvalues>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "estimators/error.h"
#include "estimators/estimator.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/kinematics/ppoe_data.h"
#include "scenarios/python/overrides.h"
#include "scenarios/runner/common/estimator_config.h"
#include "scenarios/runner/common/truth_rig.h"
#include "scenarios/runner/runner.h"
#include "sim/camera.h"
#include "sim/config.h"
#include "sim/declared_chain.h"
#include "sim/declared_model.h"
#include "sim/mujoco_model.h"
#include "sim/truth_model.h"

namespace py = pybind11;

namespace flexbench::python {
namespace {

using kinematics::FrameId;
using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// ---- One caller at a time ------------------------------------------------------------------

// MuJoCo's error and warning hooks, the OSMesa context and std::cerr (captured during a run) are
// process-wide: run_scenario, identify and DeclaredModel.load from several Python threads take
// turns. The GIL is released while waiting, so the other threads' Python code runs meanwhile.
std::mutex g_process_mutex;

// The lock, taken with the GIL held (every binding is called with it); waits without the GIL,
// so a thread holding the lock can take the GIL back.
std::unique_lock<std::mutex> LockProcess() {
  std::unique_lock<std::mutex> lock(g_process_mutex, std::try_to_lock);
  if (!lock.owns_lock()) {
    py::gil_scoped_release release;
    lock.lock();
  }
  return lock;
}

// std::cerr into `sink` for the scope (callers hold LockProcess()).
class CerrCapture {
 public:
  explicit CerrCapture(std::ostream& sink) : old_(std::cerr.rdbuf(sink.rdbuf())) {}
  ~CerrCapture() { std::cerr.rdbuf(old_); }
  CerrCapture(const CerrCapture&) = delete;
  CerrCapture& operator=(const CerrCapture&) = delete;

 private:
  std::streambuf* old_;
};

// What the runner prints for `e` (ReportError, one line on std::cerr), captured; *code is the
// exit code it returns.
std::string CliLine(const std::exception& e, int* code) {
  const std::unique_lock<std::mutex> lock = LockProcess();
  std::ostringstream text;
  {
    const CerrCapture capture(text);
    *code = scenarios::ReportError(e);
  }
  std::string line = text.str();
  while (!line.empty() && line.back() == '\n') line.pop_back();
  return line;
}

// The CLI line without the program prefix: "flexbench: error: <m>" -> "<m>".
std::string StripProgram(const std::string& line) {
  for (const char* prefix : {"flexbench: error: ", "flexbench: "}) {
    const std::string p = prefix;
    if (line.compare(0, p.size(), p) == 0) return line.substr(p.size());
  }
  return line;
}

void TranslateExceptions(std::exception_ptr p) {
  try {
    if (p) std::rethrow_exception(p);
  } catch (const ValueErrorMessage& e) {
    PyErr_SetString(PyExc_ValueError, e.what());
  } catch (const py::error_already_set&) {
    throw;  // pybind11 restores the Python error
  } catch (const py::builtin_exception&) {
    throw;  // pybind11's own (value_error, index_error, ...)
  } catch (const std::exception& e) {
    // InputError, SimulationError and filesystem errors are bad input (exit code 2):
    // ValueError with the CLI's text; anything else is an internal error.
    int code = 0;
    const std::string line = CliLine(e, &code);
    PyErr_SetString(code == scenarios::kExitBadInput ? PyExc_ValueError : PyExc_RuntimeError,
                    StripProgram(line).c_str());
  }
}

// ---- numpy input --------------------------------------------------------------------------

std::string DtypeName(const py::array& a) { return py::str(a.dtype()).cast<std::string>(); }

std::string ShapeText(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t i = 0; i < a.ndim(); ++i) {
    s += std::to_string(a.shape(i)) + (a.ndim() == 1 ? "," : (i + 1 < a.ndim() ? ", " : ""));
  }
  return s + ")";
}

// A float64 array from a numpy array (no copy) or a list/tuple of numbers (converted). Other
// dtypes are refused rather than converted: an int or float32 array is most likely a mistake.
py::array_t<double> AsFloat64(const py::handle& obj, const char* what) {
  if (py::isinstance<py::array>(obj)) {
    py::array a = py::reinterpret_borrow<py::array>(obj);
    if (!a.dtype().is(py::dtype::of<double>())) {
      throw ValueErrorMessage(std::string(what) + ": expected a float64 array, got dtype " +
                              DtypeName(a) + " (convert with .astype(float))");
    }
    return py::reinterpret_borrow<py::array_t<double>>(obj);
  }
  if (py::isinstance<py::str>(obj) || py::isinstance<py::bytes>(obj) ||
      !(py::isinstance<py::sequence>(obj) || py::isinstance<py::float_>(obj) ||
        py::isinstance<py::int_>(obj))) {
    throw ValueErrorMessage(std::string(what) +
                            ": expected a float64 array or a list of numbers, got " +
                            py::str(py::type::handle_of(obj).attr("__name__")).cast<std::string>());
  }
  py::array a;
  try {
    a = py::module_::import("numpy").attr("asarray")(obj);
  } catch (py::error_already_set&) {
    throw ValueErrorMessage(std::string(what) + ": not an array of numbers");
  }
  const char kind = a.dtype().kind();
  if (kind != 'f' && kind != 'i' && kind != 'u') {
    throw ValueErrorMessage(std::string(what) + ": expected numbers, got dtype " + DtypeName(a));
  }
  return py::array_t<double>::ensure(a);
}

// A vector of any length (1-D); `size` >= 0 requires that length.
Eigen::VectorXd ReadVector(const py::handle& obj, const char* what, int size = -1) {
  py::array_t<double> a = AsFloat64(obj, what);
  if (a.ndim() != 1 || (size >= 0 && a.shape(0) != size)) {
    throw ValueErrorMessage(std::string(what) + ": expected shape (" +
                            (size >= 0 ? std::to_string(size) : std::string("n")) +
                            ",), got shape " + ShapeText(a));
  }
  Eigen::VectorXd v(a.shape(0));
  auto r = a.unchecked<1>();
  for (py::ssize_t i = 0; i < a.shape(0); ++i) v[i] = r(i);
  return v;
}

template <int R, int C>
Eigen::Matrix<double, R, C> ReadMatrix(const py::handle& obj, const char* what) {
  py::array_t<double> a = AsFloat64(obj, what);
  if (a.ndim() != 2 || a.shape(0) != R || a.shape(1) != C) {
    throw ValueErrorMessage(std::string(what) + ": expected shape (" + std::to_string(R) + ", " +
                            std::to_string(C) + "), got shape " + ShapeText(a));
  }
  Eigen::Matrix<double, R, C> m;
  auto r = a.unchecked<2>();
  for (int i = 0; i < R; ++i) {
    for (int j = 0; j < C; ++j) m(i, j) = r(i, j);
  }
  return m;
}

template <int N>
Eigen::Matrix<double, N, 1> ReadFixedVector(const py::handle& obj, const char* what) {
  return ReadVector(obj, what, N);
}

lie::SE3 ReadPose(const py::handle& obj, const char* what) {
  const Mat4 T = ReadMatrix<4, 4>(obj, what);
  if (!T.allFinite()) throw ValueErrorMessage(std::string(what) + ": not finite");
  const Mat3 R = T.topLeftCorner<3, 3>();
  if ((R.transpose() * R - Mat3::Identity()).cwiseAbs().maxCoeff() > 1e-6 ||
      R.determinant() < 0.0) {
    throw ValueErrorMessage(std::string(what) + ": the upper-left 3x3 block is not a rotation");
  }
  return lie::SE3::FromMatrix(T);
}

// ---- numpy output -------------------------------------------------------------------------

py::array_t<double> PoseArray(const lie::SE3& T) {
  py::array_t<double> out({4, 4});
  auto w = out.mutable_unchecked<2>();
  const Mat3& R = T.rotation();
  const Vec3& t = T.translation();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) w(i, j) = R(i, j);
    w(i, 3) = t[i];
    w(3, i) = 0.0;
  }
  w(3, 3) = 1.0;
  return out;
}

template <typename Derived>
py::array_t<double> MatrixArray(const Eigen::MatrixBase<Derived>& M) {
  py::array_t<double> out({static_cast<py::ssize_t>(M.rows()), static_cast<py::ssize_t>(M.cols())});
  auto w = out.mutable_unchecked<2>();
  for (Eigen::Index i = 0; i < M.rows(); ++i) {
    for (Eigen::Index j = 0; j < M.cols(); ++j) w(i, j) = M(i, j);
  }
  return out;
}

template <typename Derived>
py::array_t<double> VectorArray(const Eigen::MatrixBase<Derived>& v) {
  py::array_t<double> out(static_cast<py::ssize_t>(v.size()));
  auto w = out.mutable_unchecked<1>();
  for (Eigen::Index i = 0; i < v.size(); ++i) w(i) = v[i];
  return out;
}

// A str argument, or ValueError naming it.
std::string StringArg(const py::handle& v, const std::string& what) {
  if (!py::isinstance<py::str>(v)) {
    throw ValueErrorMessage(what + ": expected a str, got " +
                            py::str(py::type::handle_of(v).attr("__name__")).cast<std::string>());
  }
  return v.cast<std::string>();
}

// A list or tuple argument, or ValueError naming it.
py::sequence ListArg(const py::handle& v, const std::string& what) {
  if (!(py::isinstance<py::list>(v) || py::isinstance<py::tuple>(v))) {
    throw ValueErrorMessage(what + ": expected a list of frame names");
  }
  return py::reinterpret_borrow<py::sequence>(v);
}

// ---- Declared model -----------------------------------------------------------------------

// A robot's MJCF or URDF (DeclaredModel.load builds the declared model from it) rather than a
// declared-model YAML.
bool IsRobotFile(const std::string& path) {
  const std::string ext = std::filesystem::path(path).extension().string();
  return sim::IsUrdfPath(path) || ext == ".xml" || ext == ".XML";
}

class Model {
 public:
  static std::shared_ptr<Model> Load(const std::string& path) {
    const std::unique_lock<std::mutex> lock = LockProcess();
    const py::gil_scoped_release release;
    auto m = std::shared_ptr<Model>(new Model());
    sim::DeclaredModel declared =
        IsRobotFile(path) ? sim::DeclaredModelOfRobot(path) : sim::LoadDeclaredModel(path);
    m->mj_ = sim::LoadModel(declared.model_path);
    m->rig_ = scenarios::BuildDeclaredRig(m->mj_.get(), std::move(declared));
    m->data_ = std::make_unique<kinematics::PpoeData>(m->rig_.chain->model);
    const kinematics::PpoeModel& pm = m->rig_.chain->model;
    for (FrameId i = 0; i < pm.num_frames(); ++i) m->frames_[pm.frame(i).name] = i;
    for (const auto& [name, id] : m->rig_.chain->observed) m->frames_[name] = id;
    m->frames_[m->rig_.declared.end_effector] = m->rig_.chain->end_effector;
    return m;
  }

  const kinematics::PpoeModel& ppoe() const { return rig_.chain->model; }
  const sim::DeclaredChain& chain() const { return *rig_.chain; }
  // The chain's estimator set-up (model, identified effects, end effector).
  const estimators::EstimatorSetup& setup() const { return rig_.setup; }
  const sim::DeclaredModel& declared() const { return rig_.declared; }
  const mjModel* mj() const { return mj_.get(); }
  kinematics::PpoeData& data() { return *data_; }
  int nq() const { return rig_.chain->model.nq(); }

  // A frame by id or by name: the declared end effector and observed frames by their declared
  // names, any PPOE frame by its typed name ("site/ee", "body/link3", "joint/j2", "base");
  // None is the end effector.
  FrameId Frame(const py::handle& frame) const {
    if (frame.is_none()) return rig_.chain->end_effector;
    if (py::isinstance<py::str>(frame)) {
      const std::string name = frame.cast<std::string>();
      const auto it = frames_.find(name);
      if (it != frames_.end()) return it->second;
      std::string known = "'" + rig_.declared.end_effector + "'";
      for (const auto& [n, id] : rig_.chain->observed) known += ", '" + n + "'";
      throw InputError(rig_.declared.file + ": no frame '" + CapForMessage(name) +
                       "' (the end effector and observed frames: " + known +
                       "; or a typed name such as site/<name>, body/<name>)");
    }
    if (py::isinstance<py::int_>(frame) && !py::isinstance<py::bool_>(frame)) {
      const long long id = frame.cast<long long>();
      if (id < 0 || id >= ppoe().num_frames()) {
        throw ValueErrorMessage("frame " + std::to_string(id) + ": out of range [0, " +
                                std::to_string(ppoe().num_frames()) + ")");
      }
      return static_cast<FrameId>(id);
    }
    throw ValueErrorMessage("frame: expected a frame name (str) or id (int)");
  }

  // Runs f(q) with q read in place from a contiguous float64 array (a copy otherwise).
  template <typename F>
  auto WithQ(const py::handle& q_obj, F&& f) {
    py::array_t<double> a = AsFloat64(q_obj, "q");
    if (a.ndim() != 1) {
      throw ValueErrorMessage("q: expected shape (" + std::to_string(nq()) + ",), got shape " +
                              ShapeText(a));
    }
    // A wrong length is the library's own InputError (the same text as the C++ API).
    if (a.strides(0) == static_cast<py::ssize_t>(sizeof(double))) {
      Eigen::Map<const Eigen::VectorXd> q(a.data(), a.shape(0));
      return f(Eigen::Ref<const Eigen::VectorXd>(q));
    }
    const Eigen::VectorXd q = ReadVector(a, "q");
    return f(Eigen::Ref<const Eigen::VectorXd>(q));
  }

 private:
  Model() = default;
  sim::MjModelPtr mj_;
  scenarios::DeclaredRig rig_;
  std::unique_ptr<kinematics::PpoeData> data_;
  std::unordered_map<std::string, FrameId> frames_;
};

lie::CompoundOrder Order(int order) {
  if (order == 2) return lie::CompoundOrder::kSecond;
  if (order == 4) return lie::CompoundOrder::kFourth;
  throw ValueErrorMessage("order: expected 2 or 4, got " + std::to_string(order));
}

// ---- Estimators ---------------------------------------------------------------------------

class PyEstimator {
 public:
  PyEstimator(std::shared_ptr<Model> model, std::string name, estimators::EstimatorSetup setup)
      : model_(std::move(model)), name_(std::move(name)), setup_(std::move(setup)) {
    estimator_ = estimators::MakeEstimator(name_, setup_);
  }

  const std::string& name() const { return name_; }
  Model& model() { return *model_; }
  estimators::Estimator& get() { return *estimator_; }
  const estimators::EstimatorSetup& setup() const { return setup_; }

  std::string Update(const estimators::Measurement& z) {
    return estimators::ToString(estimator_->Update(z));
  }

 private:
  std::shared_ptr<Model> model_;  // keeps the PPOE model the estimator points at alive
  std::string name_;
  estimators::EstimatorSetup setup_;
  std::unique_ptr<estimators::Estimator> estimator_;
};

// Estimator parameters go through the scenario parser as the --set overrides
// `estimators.<name>.<key>=<value>` would, so every message is the CLI's own.
std::unique_ptr<PyEstimator> MakePyEstimator(const std::string& name,
                                             const std::shared_ptr<Model>& model,
                                             const py::kwargs& kwargs) {
  if (!model) throw ValueErrorMessage("model: expected a flexbench.DeclaredModel");
  // The name and the parameter names become override keys: plain names only (no YAML syntax).
  if (!IsPlainDottedKey(name, false)) {
    throw ValueErrorMessage("estimator name '" + CapForMessage(name) +
                            "': expected letters, digits and '_' (flexbench.estimator_names())");
  }
  estimators::EstimatorSetup setup = model->setup();
  std::vector<ConfigOverride> overrides;
  double imu_beta = estimators::ImuSetup{}.filter_beta;
  std::vector<Quat> imu_initial;
  for (const auto& [key_obj, value] : kwargs) {
    const std::string key = Utf8(key_obj, "a parameter name");
    if (key == "imu_beta") {
      if (!py::isinstance<py::float_>(value) && !py::isinstance<py::int_>(value)) {
        throw ValueErrorMessage("imu_beta: expected a number > 0");
      }
      imu_beta = value.cast<double>();
      if (!(imu_beta > 0.0) || !std::isfinite(imu_beta)) {
        throw ValueErrorMessage("imu_beta: expected a finite number > 0");
      }
    } else if (key == "imu_initial") {
      for (const auto& q : ListArg(value, "imu_initial")) {
        const Vec4 v = ReadFixedVector<4>(q, "imu_initial");
        if (!(v.norm() > 0.0)) throw ValueErrorMessage("imu_initial: a quaternion of norm 0");
        imu_initial.push_back(QuatFromWxyz(v.data()));
      }
    } else if (key == "seed") {
      if (!py::isinstance<py::int_>(value) || value.cast<long long>() < 0) {
        throw ValueErrorMessage("seed: expected an int >= 0");
      }
      setup.seed = value.cast<std::uint64_t>();
    } else if (key == "estimate_in") {
      setup.reference_frame = model->chain().ObservedFrame(StringArg(value, "estimate_in"));
    } else if (key == "camera_frames") {
      for (const auto& c : ListArg(value, "camera_frames")) {
        const std::string cam = StringArg(c, "camera_frames");
        const int cam_id = sim::CameraId(model->mj(), cam, model->declared().model_path);
        setup.cameras.push_back(
            {sim::CameraIntrinsics(model->mj(), cam_id), model->chain().ObservedFrame(cam)});
      }
    } else if (key == "imu_frames") {
      for (const auto& f : ListArg(value, "imu_frames")) setup.imus.push_back({model->Frame(f)});
    } else {
      if (!IsPlainDottedKey(key, false)) {
        throw ValueErrorMessage("parameter '" + CapForMessage(key) +
                                "': expected letters, digits and '_'");
      }
      overrides.push_back(
          {"estimators." + name + "." + key, YamlText(value, "parameter '" + key + "'")});
    }
  }
  if (!imu_initial.empty() && imu_initial.size() != setup.imus.size()) {
    throw ValueErrorMessage("imu_initial: " + std::to_string(imu_initial.size()) +
                            " orientations for " + std::to_string(setup.imus.size()) +
                            " imu_frames");
  }
  for (size_t k = 0; k < setup.imus.size(); ++k) {
    setup.imus[k].filter_beta = imu_beta;
    if (k < imu_initial.size()) {
      setup.imus[k].has_initial = true;
      setup.imus[k].q_base_frame_initial = imu_initial[k];
    }
  }
  if (overrides.empty()) overrides.push_back({"estimators." + name, "{}"});
  const ConfigNode root =
      ConfigNode::LoadString("estimators: {}\n", "flexbench.make_estimator", overrides);
  const std::vector<scenarios::EstimatorSpec> specs =
      scenarios::ParseEstimators(root.Child("estimators"));
  setup.params = specs.at(0).params;
  return std::make_unique<PyEstimator>(model, name, setup);
}

// ---- Noise and time of a reading ----------------------------------------------------------
// A reading's values (angles, pixels, points) that are not finite are the sensor's: the
// estimator rejects them ('rejected_non_finite'). Its time and its noise are the caller's
// statement about it: a time that is not finite, a std that is not > 0 or a covariance that is
// not a covariance would be taken as given and spoil the belief, so they raise ValueError.

std::string Shown(double v) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.6g", v);
  return buf;
}

double CheckTime(double t) {
  if (!std::isfinite(t)) throw ValueErrorMessage("t: expected a finite time, got " + Shown(t));
  return t;
}

double CheckStd(double v, const std::string& what) {
  if (!(std::isfinite(v) && v > 0.0)) {
    throw ValueErrorMessage(what + ": expected a finite noise std > 0, got " + Shown(v));
  }
  return v;
}

// A covariance: finite, symmetric, and positive definite (semi-definite with `allow_singular`,
// e.g. a plane known exactly is all zeros).
template <int N>
Eigen::Matrix<double, N, N> CheckCovariance(const Eigen::Matrix<double, N, N>& c, const char* what,
                                            bool allow_singular) {
  if (!c.allFinite()) throw ValueErrorMessage(std::string(what) + ": not finite");
  const double scale = c.cwiseAbs().maxCoeff();
  if ((c - c.transpose()).cwiseAbs().maxCoeff() > 1e-9 * scale) {
    throw ValueErrorMessage(std::string(what) + ": not symmetric");
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> eig(c);
  const double smallest = eig.eigenvalues().minCoeff();
  if (allow_singular ? smallest < -1e-12 * scale : !(smallest > 0.0)) {
    throw ValueErrorMessage(std::string(what) + ": not positive " +
                            (allow_singular ? "semi-definite" : "definite") +
                            " (smallest eigenvalue " + Shown(smallest) + ")");
  }
  return c;
}

template <int N>
Eigen::Matrix<double, N, N> CovOr(const py::object& obj, const char* what) {
  if (obj.is_none()) return Eigen::Matrix<double, N, N>::Identity();
  return CheckCovariance<N>(ReadMatrix<N, N>(obj, what), what, false);
}

// ---- run / identify -----------------------------------------------------------------------

// Runs a runner command with std::cerr captured; bad input (exit code 2) raises ValueError with
// the CLI's message, an internal error (1) RuntimeError; other lines go to sys.stderr. Returns
// summary.json of `out` as a dict.
template <typename F>
py::object RunCommand(F&& command, const std::string& out) {
  std::ostringstream text;
  int code = 0;
  {
    const std::unique_lock<std::mutex> lock = LockProcess();
    py::gil_scoped_release release;
    const CerrCapture capture(text);
    try {
      code = command();
    } catch (const std::exception&) {
      throw;
    } catch (...) {
      throw std::runtime_error("unknown C++ exception");
    }
  }
  std::istringstream lines(text.str());
  std::string line, error;
  py::object sys_stderr = py::module_::import("sys").attr("stderr");
  while (std::getline(lines, line)) {
    if (line.compare(0, 11, "flexbench: ") == 0) {
      error = line;
    } else {
      py::print(line, py::arg("file") = sys_stderr);
    }
  }
  if (code == scenarios::kExitBadInput) throw ValueErrorMessage(StripProgram(error));
  if (code != scenarios::kExitOk && code != scenarios::kExitGateFailed) {
    throw std::runtime_error(error.empty() ? "exit code " + std::to_string(code)
                                           : StripProgram(error));
  }
  const std::string summary = (std::filesystem::path(out) / "summary.json").string();
  py::object json = py::module_::import("json");
  py::object f =
      py::module_::import("io").attr("open")(summary, "r", py::arg("encoding") = "utf-8");
  py::object result = json.attr("load")(f);
  f.attr("close")();
  return result;
}

using ModelClass = py::class_<Model, std::shared_ptr<Model>>;
using EstimatorClass = py::class_<PyEstimator>;

// ---- Bindings ---------------------------------------------------------------------------

// DeclaredModel: fk, fk_cov and jacobian.
void BindModelKinematics(ModelClass& cls) {
  cls.def(
         "fk",
         [](Model& self, const py::object& q, const py::object& frame) {
           const FrameId f = self.Frame(frame);
           return self.WithQ(q, [&](const Eigen::Ref<const Eigen::VectorXd>& qv) {
             kinematics::ForwardKinematics(self.ppoe(), self.data(), qv);
             return PoseArray(self.data().T_base_frame[f]);
           });
         },
         py::arg("q"), py::arg("frame") = py::none(),
         "Mean pose T_base_frame(q) as a 4x4 array (no identified effects applied).")
      .def(
          "fk_cov",
          [](Model& self, const py::object& q, const py::object& frame, int order) {
            const FrameId f = self.Frame(frame);
            const lie::CompoundOrder o = Order(order);
            return self.WithQ(q, [&](const Eigen::Ref<const Eigen::VectorXd>& qv) {
              kinematics::ForwardKinematicsWithCovariance(self.ppoe(), self.data(), qv, o);
              return py::make_tuple(PoseArray(self.data().T_base_frame[f]),
                                    MatrixArray(self.data().Sigma_frame[f]));
            });
          },
          py::arg("q"), py::arg("frame") = py::none(), py::arg("order") = 2,
          "(T 4x4, Sigma 6x6): mean pose and its covariance in the local tangent space "
          "([rho; theta]), compounded to 2nd or 4th order [PPOE eq. 18].")
      .def(
          "jacobian",
          [](Model& self, const py::object& q, const py::object& frame) {
            const FrameId f = self.Frame(frame);
            return self.WithQ(q, [&](const Eigen::Ref<const Eigen::VectorXd>& qv) {
              kinematics::ForwardKinematics(self.ppoe(), self.data(), qv);
              kinematics::Matrix6Xd J(6, self.nq());
              kinematics::ComputeFrameJacobian(self.ppoe(), self.data(), f, J);
              return MatrixArray(J);
            });
          },
          py::arg("q"), py::arg("frame") = py::none(),
          "6 x nq local Jacobian: T(q + dq) = T(q) Exp(J dq) to first order.");
}

// DeclaredModel: loading, names, frames, its kinematics.
void BindDeclaredModel(py::module_& m) {
  ModelClass cls(m, "DeclaredModel",
                 "A declared model (models/<name>.declared.yaml) built "
                 "into its PPOE chain from the MuJoCo model it names.");
  // Outlives the module: pybind11 keeps the pointer.
  static const std::string load_doc =
      "Loads a declared-model YAML file (and the MJCF/URDF it names), or a robot's URDF or MJCF "
      "(.urdf, .xml) without one: actuated joints are the joints the truth commands (every "
      "hinge and slide of a URDF; an MJCF's <position> servos), the end effector the body at "
      "the end of the chain past the last of them, a source of " +
      [] {
        char b[32];
        std::snprintf(b, sizeof(b), "%g", sim::kDefaultSourceDeg);
        return std::string(b);
      }() +
      " deg about each joint's axis. Calls from several threads are serialised, with "
      "run_scenario and identify.";
  cls.def_static("load", &Model::Load, py::arg("path"), load_doc.c_str())
      .def_property_readonly("nq", &Model::nq, "number of joint variables (len(q))")
      .def_property_readonly(
          "joint_names", [](const Model& self) { return self.chain().q_joints; },
          "MJCF joint of each entry of q")
      .def_property_readonly(
          "frame_names",
          [](const Model& self) {
            std::vector<std::string> names;
            for (const auto& f : self.ppoe().frames()) names.push_back(f.name);
            return names;
          },
          "typed names of the PPOE frames, by id")
      .def_property_readonly("end_effector",
                             [](const Model& self) { return self.declared().end_effector; })
      .def_property_readonly("observed_frames",
                             [](const Model& self) { return self.declared().observed_frames; })
      .def_property_readonly("file", [](const Model& self) { return self.declared().file; })
      .def_property_readonly("model_path",
                             [](const Model& self) { return self.declared().model_path; })
      .def(
          "frame_id", [](const Model& self, const py::object& frame) { return self.Frame(frame); },
          py::arg("frame"), "id of a frame given by name (or id, checked)");
  BindModelKinematics(cls);
  cls.def("__repr__", [](const Model& self) {
    return "<flexbench.DeclaredModel '" + self.declared().file +
           "' nq=" + std::to_string(self.nq()) + ">";
  });
}

// Estimator: encoder, IMU and orientation readings.
void BindReadingUpdates(EstimatorClass& cls) {
  cls.def(
         "update_joints",
         [](PyEstimator& self, double t, const py::object& q, const py::object& std) {
           const int nq = self.model().nq();
           if (nq > estimators::kMaxJoints) throw ValueErrorMessage("too many joints");
           estimators::JointReading z;
           z.t = CheckTime(t);
           z.q = ReadVector(q, "q", nq);
           if (py::isinstance<py::float_>(std) ||
               (py::isinstance<py::int_>(std) && !py::isinstance<py::bool_>(std))) {
             z.std = estimators::JointVector::Constant(nq, CheckStd(std.cast<double>(), "std"));
           } else {
             z.std = ReadVector(std, "std", nq);
             for (int i = 0; i < nq; ++i) CheckStd(z.std[i], "std[" + std::to_string(i) + "]");
           }
           return self.Update(z);
         },
         py::arg("t"), py::arg("q"), py::arg("std"),
         "Encoder readings (rad or m, in q order) with their noise std (> 0, scalar or per "
         "joint). Returns the update status ('accepted', 'ignored', 'rejected_non_finite', ...); "
         "a time that is not finite or a std that is not > 0 raises ValueError.")
      .def(
          "update_imu",
          [](PyEstimator& self, double t, const py::object& gyro, const py::object& accel,
             int imu) {
            estimators::ImuReading z;
            z.t = CheckTime(t);
            z.imu = imu;
            z.gyro = ReadFixedVector<3>(gyro, "gyro");
            z.accel = ReadFixedVector<3>(accel, "accel");
            return self.Update(z);
          },
          py::arg("t"), py::arg("gyro"), py::arg("accel"), py::arg("imu") = 0,
          "A raw IMU reading of imu_frames[imu]: gyro (rad/s) and accelerometer (m/s^2, +g up at "
          "rest), in the sensor frame. The estimators that use IMU orientations (pf_encoders_imu, "
          "pf_all, pf_bingham_*, direct_fusion_*) run it through that IMU's Madgwick filter; the "
          "particle filters weigh the orientation at the step's update_joints (one term per IMU "
          "per step). The others return 'ignored'.")
      .def(
          "update_orientation",
          [](PyEstimator& self, double t, const py::object& frame, const py::object& wxyz) {
            estimators::OrientationReading z;
            z.t = CheckTime(t);
            z.frame = self.model().Frame(frame);
            const Vec4 v = ReadFixedVector<4>(wxyz, "q_base_frame");
            z.q_base_frame = QuatFromWxyz(v.data());
            return self.Update(z);
          },
          py::arg("t"), py::arg("frame"), py::arg("q_base_frame"),
          "orientation of a frame in the base as a quaternion [w, x, y, z]");
}

// Estimator: pixel and tag-corner readings.
void BindCameraUpdates(EstimatorClass& cls) {
  cls.def(
         "update_pixel",
         [](PyEstimator& self, double t, const py::object& frame, const py::object& p_frame,
            const py::object& uv, const py::object& cov, int camera) {
           estimators::PixelPoint z;
           z.t = CheckTime(t);
           z.camera = camera;
           z.frame = self.model().Frame(frame);
           z.p_frame = ReadFixedVector<3>(p_frame, "p_frame");
           z.uv = ReadFixedVector<2>(uv, "uv");
           z.cov = CovOr<2>(cov, "cov");
           return self.Update(z);
         },
         py::arg("t"), py::arg("frame"), py::arg("p_frame"), py::arg("uv"),
         py::arg("cov") = py::none(), py::arg("camera") = 0)
      .def(
          "update_tag",
          [](PyEstimator& self, double t, const py::object& frame, const py::object& p_frame,
             const py::object& uv, const py::object& cov, int camera, int tag_id) {
            estimators::TagCorners z;
            z.t = CheckTime(t);
            z.camera = camera;
            z.tag_id = tag_id;
            z.frame = self.model().Frame(frame);
            const Eigen::Matrix<double, 4, 3> p = ReadMatrix<4, 3>(p_frame, "p_frame");
            const Eigen::Matrix<double, 4, 2> c = ReadMatrix<4, 2>(uv, "uv");
            for (int k = 0; k < 4; ++k) {
              z.p_frame[k] = p.row(k).transpose();
              z.uv[k] = c.row(k).transpose();
            }
            z.cov = CovOr<8>(cov, "cov");
            return self.Update(z);
          },
          py::arg("t"), py::arg("frame"), py::arg("p_frame"), py::arg("uv"),
          py::arg("cov") = py::none(), py::arg("camera") = 0, py::arg("tag_id") = -1,
          "the four corners of a tag (4x3 points in the frame, 4x2 pixels, 8x8 covariance)");
}

// Estimator: plane contacts, positions and poses.
void BindGeometryUpdates(EstimatorClass& cls) {
  cls.def(
         "update_contact",
         [](PyEstimator& self, double t, const py::object& frame, const py::object& p_frame,
            const py::object& T_base_plane, const py::object& plane_cov, double distance,
            double std) {
           estimators::PlaneContact z;
           z.t = CheckTime(t);
           z.frame = self.model().Frame(frame);
           z.p_frame = ReadFixedVector<3>(p_frame, "p_frame");
           z.T_base_plane = ReadPose(T_base_plane, "T_base_plane");
           z.plane_cov = plane_cov.is_none()
                             ? Mat6(Mat6::Zero())
                             : CheckCovariance<6>(ReadMatrix<6, 6>(plane_cov, "plane_cov"),
                                                  "plane_cov", true);
           z.distance = distance;
           z.std = CheckStd(std, "std");
           return self.Update(z);
         },
         py::arg("t"), py::arg("frame"), py::arg("p_frame"), py::arg("T_base_plane"),
         py::arg("plane_cov") = py::none(), py::arg("distance") = 0.0, py::arg("std") = 1e-3)
      .def(
          "update_position",
          [](PyEstimator& self, double t, const py::object& frame, const py::object& p_frame,
             const py::object& p_base, const py::object& cov) {
            estimators::PositionReading z;
            z.t = CheckTime(t);
            z.frame = self.model().Frame(frame);
            z.p_frame = ReadFixedVector<3>(p_frame, "p_frame");
            z.p_base = ReadFixedVector<3>(p_base, "p_base");
            z.cov = CovOr<3>(cov, "cov");
            return self.Update(z);
          },
          py::arg("t"), py::arg("frame"), py::arg("p_frame"), py::arg("p_base"),
          py::arg("cov") = py::none())
      .def(
          "update_pose",
          [](PyEstimator& self, double t, const py::object& frame, const py::object& T,
             const py::object& cov) {
            estimators::PoseReading z;
            z.t = CheckTime(t);
            z.frame = self.model().Frame(frame);
            z.T_base_frame = ReadPose(T, "T_base_frame");
            z.cov = CovOr<6>(cov, "cov");
            return self.Update(z);
          },
          py::arg("t"), py::arg("frame"), py::arg("T_base_frame"), py::arg("cov") = py::none());
}

// Estimator: its belief and its updates by reading type.
void BindEstimator(py::module_& m) {
  EstimatorClass cls(m, "Estimator", "An estimator made by flexbench.make_estimator.");
  cls.def_property_readonly("name", &PyEstimator::name)
      .def("reset", [](PyEstimator& self) { self.get().Reset(); })
      .def(
          "predict", [](PyEstimator& self, double t) { self.get().Predict(CheckTime(t)); },
          py::arg("t"))
      .def(
          "estimate",
          [](PyEstimator& self) {
            const estimators::Belief b = self.get().Estimate();
            return py::make_tuple(PoseArray(b.T_base_ee), MatrixArray(b.cov));
          },
          "(T 4x4, Sigma 6x6): the end-effector pose (in the base, or estimate_in) and its "
          "covariance in the local tangent space.")
      .def(
          "belief",
          [](PyEstimator& self) {
            const estimators::Belief b = self.get().Estimate();
            py::dict d;
            d["t"] = b.t;
            d["T"] = PoseArray(b.T_base_ee);
            d["cov"] = MatrixArray(b.cov);
            d["q"] = b.has_joints ? py::object(VectorArray(b.q)) : py::none();
            d["q_std"] = b.has_joints ? py::object(VectorArray(b.q_std)) : py::none();
            return d;
          },
          "the whole belief as a dict: t, T, cov, q and q_std (None without joints)")
      .def_property_readonly("covariance_repairs",
                             [](PyEstimator& self) { return self.get().covariance_repairs(); });
  BindReadingUpdates(cls);
  BindCameraUpdates(cls);
  BindGeometryUpdates(cls);
  cls.def("__repr__",
          [](const PyEstimator& self) { return "<flexbench.Estimator '" + self.name() + "'>"; });
}

// make_estimator and estimator_names.
void BindEstimatorRegistry(py::module_& m) {
  m.def("make_estimator", &MakePyEstimator, py::arg("name"), py::arg("model"),
        "make_estimator(name, model, *, seed=0, estimate_in=None, camera_frames=(), "
        "imu_frames=(), imu_beta=0.05, imu_initial=None, **params): an estimator of the "
        "registry by name with its scenario-file parameters (numbers or lists of numbers). "
        "seed, estimate_in (an observed frame), camera_frames (MuJoCo cameras among the "
        "observed frames, intrinsics from the model) and imu_frames are the set-up a scenario "
        "kind would give it; imu_beta is the IMUs' Madgwick gain (rad/s), imu_initial one "
        "[w, x, y, z] orientation in the base frame per IMU at its first reading (else the "
        "first accelerometer reading's, yaw 0).");

  m.def("estimator_names", [] {
    std::vector<std::string> names;
    for (const auto& e : estimators::EstimatorRegistry()) names.push_back(e.name);
    return names;
  });
}

// run_scenario: `flexbench run`.
void BindRunScenario(py::module_& m) {
  m.def(
      "run_scenario",
      [](const std::string& path, const std::string& out, std::optional<std::uint64_t> seed,
         const py::object& overrides, bool force) {
        scenarios::RunOptions o;
        o.scenario_path = path;
        o.out_dir = out;
        o.seed = seed;
        o.set = OverrideArgs(overrides);
        o.force = force;
        o.quiet = true;
        return RunCommand([&] { return scenarios::RunScenario(o); }, out);
      },
      py::arg("path"), py::arg("out"), py::arg("seed") = py::none(),
      py::arg("overrides") = py::dict(), py::arg("force") = false,
      "`flexbench run PATH --out OUT [--seed S] [--set K=V ...] --quiet`; returns "
      "OUT/summary.json as a dict. overrides: {dotted.key: value} or ['KEY=VALUE', ...] (keys "
      "are names of letters, digits and '_' separated by '.'). Bad input, including a fatal "
      "MuJoCo error, raises ValueError and leaves nothing behind. Calls from several threads "
      "are serialised (one runs at a time; the others wait without holding the GIL).");
}

// identify: `flexbench identify`.
void BindIdentify(py::module_& m) {
  m.def(
      "identify",
      [](const std::string& declared, const std::string& calibration, const std::string& validation,
         const std::string& out, const std::string& model,
         const std::vector<std::string>& candidates, double point_std,
         std::optional<double> reading_std_deg, std::optional<int> max_effects,
         std::optional<double> bic_threshold, std::optional<std::string> folds_by,
         std::optional<double> outlier_iqr, bool no_cross_validation, const py::object& overrides,
         bool force) {
        scenarios::IdentifyCliOptions o;
        o.declared = declared;
        o.calibration_csv = calibration;
        o.validation_csv = validation;
        o.out_dir = out;
        o.model = model;
        o.candidates = candidates;
        o.point_std_m = point_std;
        o.reading_std_deg = reading_std_deg;
        o.max_effects = max_effects;
        o.bic_threshold = bic_threshold;
        o.folds_by = folds_by;
        o.outlier_iqr = outlier_iqr;
        o.no_cross_validation = no_cross_validation;
        o.set = OverrideArgs(overrides);
        o.force = force;
        o.quiet = true;
        return RunCommand([&] { return scenarios::IdentifyCommand(o); }, out);
      },
      py::arg("declared"), py::arg("calibration"), py::arg("validation"),
      py::arg("out") = "out/identify", py::arg("model") = "",
      py::arg("candidates") = std::vector<std::string>{}, py::arg("point_std") = 1e-4,
      py::arg("reading_std_deg") = py::none(), py::arg("max_effects") = py::none(),
      py::arg("bic_threshold") = py::none(), py::arg("folds_by") = py::none(),
      py::arg("outlier_iqr") = py::none(), py::arg("no_cross_validation") = false,
      py::arg("overrides") = py::dict(), py::arg("force") = false,
      "`flexbench identify` with the same options (--calibration -> calibration, --set -> "
      "overrides, ...); returns OUT/summary.json as a dict. Calls from several threads are "
      "serialised, with run_scenario and DeclaredModel.load.");
}

void BindBenchmark(py::module_& m) {
  // The C++ side of the benchmark (scripts/bench_python.py): n calls of
  // ForwardKinematicsWithCovariance on a preallocated workspace, in seconds.
  m.def(
      "_bench_fk_cov",
      [](Model& self, const py::object& q, int n, int order) {
        const lie::CompoundOrder o = Order(order);
        const Eigen::VectorXd qv = ReadVector(q, "q", self.nq());
        const auto t0 = std::chrono::steady_clock::now();
        for (int i = 0; i < n; ++i) {
          kinematics::ForwardKinematicsWithCovariance(self.ppoe(), self.data(), qv, o);
        }
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      },
      py::arg("model"), py::arg("q"), py::arg("n"), py::arg("order") = 2);
}

}  // namespace
}  // namespace flexbench::python

using namespace flexbench;
using namespace flexbench::python;

PYBIND11_MODULE(flexbench, m) {
  m.doc() =
      "flexbench: declared PPOE models, probabilistic forward kinematics, the estimators by "
      "name, and the runner (run_scenario, identify). See docs/python.md.";
  m.attr("__version__") = FLEXBENCH_VERSION;
  // numpy carries every array in and out. A pyenv or conda interpreter can import the module
  // built for /usr/bin/python3 without having numpy: say so now, naming the interpreter.
  try {
    py::module_::import("numpy");
  } catch (const py::error_already_set&) {
    const std::string exe = py::module_::import("sys").attr("executable").cast<std::string>();
    throw py::import_error("flexbench needs numpy, which the interpreter importing it (" + exe +
                           ") does not have: run /usr/bin/python3 (Debian's python3-numpy), or "
                           "install numpy for this interpreter");
  }
  py::register_local_exception_translator(&TranslateExceptions);
  // Before any MuJoCo call: its fatal errors must throw, never end the interpreter.
  sim::InstallMujocoHandlers();

  BindDeclaredModel(m);
  BindEstimator(m);
  BindEstimatorRegistry(m);
  BindRunScenario(m);
  BindIdentify(m);
  BindBenchmark(m);
}
