#include "scenarios/runner/common/log_replay.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <utility>

#include "estimators/error.h"

namespace flexbench::scenarios {
namespace {

// Indices of `rows` in time order (a stream's own order where times are equal).
template <typename Row>
std::vector<size_t> TimeOrder(const std::vector<Row>& rows) {
  std::vector<size_t> order(rows.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return rows[a].t < rows[b].t; });
  return order;
}

// fn(row) for the rows of `order` (indices into `rows`, in time order) from *next on while
// their time is at most t.
template <typename Row, typename Fn>
void UpTo(const std::vector<size_t>& order, const std::vector<Row>& rows, double t, size_t* next,
          Fn fn) {
  for (; *next < order.size() && rows[order[*next]].t <= t; ++*next) fn(rows[order[*next]]);
}

// A frame orientations.csv, positions.csv or a contact point is on: the end effector or an
// observed frame.
kinematics::FrameId SensedFrame(const sim::DeclaredChain& chain, const std::string& name) {
  if (chain.end_effector_name == name) return chain.end_effector;
  return chain.ObservedFrame(name);
}

}  // namespace

estimators::EstimatorSetup LogEstimatorSetup(const sim::RecordedLog& log,
                                             const sim::DeclaredChain& chain,
                                             const std::string& end_effector) {
  const std::string log_yaml = log.dir + "/log.yaml";
  estimators::EstimatorSetup setup;
  setup.model = &chain.model;
  setup.effects = chain.effects_or_null();
  setup.end_effector = chain.end_effector;
  for (const sim::LogImu& imu : log.imus) {
    estimators::ImuSetup s;
    try {
      s.frame = chain.ObservedFrame(imu.frame);
    } catch (const InputError& e) {
      throw InputError(log_yaml + ": imu.sensors." + imu.name + ".frame: " + e.what());
    }
    s.filter_beta = imu.filter_beta;
    s.has_initial = imu.has_initial;
    s.q_base_frame_initial = imu.q_base_frame_initial;
    setup.imus.push_back(s);
  }
  // The frames orientations.csv reads are the estimators' orientation-sensed frames too (the
  // filters' IMU terms), after imu.csv's sensors, in the order the file first names them.
  std::vector<int> oriented;
  for (const sim::LogOrientationRow& row : log.orientations) {
    if (std::find(oriented.begin(), oriented.end(), row.frame) == oriented.end()) {
      oriented.push_back(row.frame);
    }
  }
  for (int f : oriented) {
    estimators::ImuSetup s;
    try {
      s.frame = SensedFrame(chain, log.sensed_frames[f]);
    } catch (const InputError& e) {
      throw InputError(log_yaml + ": orientations: frame '" + log.sensed_frames[f] +
                       "': " + e.what());
    }
    const bool known =
        std::any_of(setup.imus.begin(), setup.imus.end(),
                    [&](const estimators::ImuSetup& i) { return i.frame == s.frame; });
    if (!known) setup.imus.push_back(s);
  }
  for (const sim::LogCamera& cam : log.cameras) {
    try {
      setup.cameras.push_back({cam.intrinsics, chain.ObservedFrame(cam.frame)});
    } catch (const InputError& e) {
      throw InputError(log_yaml + ": cameras." + cam.name + ".frame: " + e.what());
    }
  }
  if (!log.estimate_in.empty()) {
    try {
      setup.reference_frame = chain.ObservedFrame(log.estimate_in);
    } catch (const InputError& e) {
      throw InputError(log_yaml + ": estimate_in: " + e.what());
    }
  }
  if (!log.truth_t.empty() && log.truth_frame != end_effector) {
    throw InputError(log_yaml + ": truth.frame '" + log.truth_frame +
                     "': the estimators estimate the declared end effector '" + end_effector + "'");
  }
  return setup;
}

DeclaredRig BuildLogRig(const sim::RecordedLog& log, const mjModel* nominal,
                        sim::DeclaredModel declared, LogIndex* index) {
  DeclaredRig rig = BuildDeclaredRig(nominal, std::move(declared));
  *index = IndexLog(log, *rig.chain, rig.declared.file);
  rig.setup = LogEstimatorSetup(log, *rig.chain, rig.declared.end_effector);
  return rig;
}

LogIndex IndexLog(const sim::RecordedLog& log, const sim::DeclaredChain& chain,
                  const std::string& declared_file) {
  LogIndex index;
  const kinematics::PpoeModel& model = chain.model;
  std::vector<char> slide;
  for (int k = 0; k < model.nq(); ++k) {
    slide.push_back(model.frame(model.joint_frame(k)).joint.type ==
                    kinematics::JointType::kPrismatic);
  }
  index.column = sim::JointColumns(log, chain.q_joints, slide, declared_file);
  for (const sim::LogTag& tag : log.tags) {
    try {
      index.tag_frame.push_back(chain.ObservedFrame(tag.frame));
    } catch (const InputError& e) {
      throw InputError(log.dir + "/log.yaml: tags.ids." + std::to_string(tag.id) +
                       ".frame: " + e.what());
    }
  }
  for (const sim::LogContactPoint& point : log.contact_points) {
    try {
      index.contact_frame.push_back(SensedFrame(chain, point.frame));
    } catch (const InputError& e) {
      throw InputError(log.dir + "/log.yaml: contacts.points." + point.name +
                       ".frame: " + e.what());
    }
  }
  for (const std::string& frame : log.sensed_frames) {
    try {
      index.sensed_frame.push_back(SensedFrame(chain, frame));
    } catch (const InputError& e) {
      throw InputError(log.dir + "/log.yaml: orientations or positions: frame '" + frame +
                       "': " + e.what());
    }
  }
  index.contact_order = TimeOrder(log.contacts);
  index.tag_order = TimeOrder(log.tag_rows);
  index.orientation_order = TimeOrder(log.orientations);
  index.position_order = TimeOrder(log.positions);
  return index;
}

std::vector<LogStep> LogSteps(const sim::RecordedLog& log, double step_hz, double t_from,
                              double t_to) {
  std::vector<LogStep> steps;
  const std::vector<double>& t = log.joint_t;
  const auto keep = [&](size_t r) {
    if (t[r] >= t_from && t[r] <= t_to) steps.push_back({t[r], r});
  };
  if (step_hz == 0.0) {
    for (size_t r = 0; r < t.size(); ++r) keep(r);
    return steps;
  }
  // Each tick k (at t.front() + k / step_hz) takes the latest row at or before it, at that
  // row's time: row r is stepped when a tick falls in [t_r, t_r+1), or at t_r for the last
  // row. In ticks, with a thousandth of a tick of slack for times written in decimals.
  const auto first_tick_at_or_after = [&](double time) {
    return std::ceil((time - t.front()) * step_hz - 1e-3);
  };
  for (size_t r = 0; r < t.size(); ++r) {
    const double k = first_tick_at_or_after(t[r]);
    const bool served = r + 1 < t.size() ? k < first_tick_at_or_after(t[r + 1])
                                         : k <= (t[r] - t.front()) * step_hz + 1e-3;
    if (served) keep(r);
  }
  return steps;
}

std::vector<size_t> ImuTimeOrder(const sim::RecordedLog& log) { return TimeOrder(log.imu); }

int ReplayLog(const sim::RecordedLog& log, const LogIndex& index, const std::vector<LogStep>& steps,
              const std::vector<size_t>& imu_order, estimators::Estimator& est,
              const std::function<void(size_t, const estimators::Belief&)>& on_step) {
  int rejected = 0;
  const auto count = [&](estimators::UpdateStatus s) {
    rejected += s != estimators::UpdateStatus::kAccepted && s != estimators::UpdateStatus::kIgnored;
  };
  const std::vector<int>& column = index.column;
  estimators::JointReading j;
  j.q.resize(static_cast<int>(column.size()));
  j.std = estimators::JointVector::Constant(static_cast<int>(column.size()), log.joint_std);
  estimators::TagCorners corners;
  corners.cov *= log.pixel_std_px * log.pixel_std_px;
  estimators::PixelPoint centre;  // tags.measurement: centre
  centre.cov = Eigen::Matrix2d::Identity() * (log.pixel_std_px * log.pixel_std_px);
  estimators::PlaneContact contact;
  estimators::OrientationReading orientation;
  estimators::PositionReading position;
  size_t next_imu = 0, next_tag = 0, next_contact = 0, next_orientation = 0, next_position = 0,
         next_posture = 0;
  for (size_t s = 0; s < steps.size(); ++s) {
    const LogStep& step = steps[s];
    UpTo(imu_order, log.imu, step.t, &next_imu,
         [&](const estimators::ImuReading& r) { count(est.Update(r)); });
    // A posture of its own (a static-posture row, or one postures.csv begins): estimated afresh.
    bool fresh = log.static_postures;
    for (; next_posture < log.posture_starts.size() && log.posture_starts[next_posture] <= step.t;
         ++next_posture) {
      fresh = true;
    }
    if (fresh) est.Reset();
    est.Predict(step.t);
    j.t = step.t;
    for (int k = 0; k < j.q.size(); ++k) j.q[k] = log.q(step.row)[column[k]];
    count(est.Update(j));
    UpTo(index.orientation_order, log.orientations, step.t, &next_orientation,
         [&](const sim::LogOrientationRow& row) {
           orientation.t = row.t;
           orientation.frame = index.sensed_frame[row.frame];
           orientation.q_base_frame = row.q_base_frame;
           count(est.Update(orientation));
         });
    UpTo(index.position_order, log.positions, step.t, &next_position,
         [&](const sim::LogPositionRow& row) {
           position.t = row.t;
           position.frame = index.sensed_frame[row.frame];
           position.p_base = row.p_base;
           position.cov = Mat3::Identity() * (row.std_m * row.std_m);
           count(est.Update(position));
         });
    UpTo(index.tag_order, log.tag_rows, step.t, &next_tag, [&](const sim::LogTagRow& row) {
      const sim::LogTag& tag = log.tags[row.tag];
      if (log.tag_centres) {
        centre.t = row.t;
        centre.camera = row.camera;
        centre.frame = index.tag_frame[row.tag];
        centre.p_frame = sim::TagCentre(tag.corners_m);
        centre.uv = row.centre;
        count(est.Update(centre));
        return;
      }
      corners.t = row.t;
      corners.camera = row.camera;
      corners.tag_id = tag.id;
      corners.frame = index.tag_frame[row.tag];
      corners.p_frame = tag.corners_m;
      corners.uv = row.uv;
      count(est.Update(corners));
    });
    UpTo(index.contact_order, log.contacts, step.t, &next_contact,
         [&](const sim::LogContactRow& row) {
           const sim::LogPlane& plane = log.planes[row.plane];
           contact.t = row.t;
           contact.frame = index.contact_frame[row.point];
           contact.p_frame = log.contact_points[row.point].p_frame;
           contact.T_base_plane = plane.T_base_plane;
           contact.plane_cov = plane.cov;
           contact.distance = row.distance_m;
           contact.std = row.std_m;
           count(est.Update(contact));
         });
    on_step(s, est.Estimate());
  }
  return rejected + est.deferred_rejections();
}

}  // namespace flexbench::scenarios
