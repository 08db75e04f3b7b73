#include "scenarios/identify/dynamic/rollout.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "estimators/error.h"

namespace flexbench::identify::dynamic {
namespace {

// The terms as one truth effect of the simulation.
class TermsEffect : public sim::Effect {
 public:
  explicit TermsEffect(std::vector<DynamicTerm> terms) : terms_(std::move(terms)) {
    set_identity("dynamic_terms", "dynamic identification");
  }
  void Configure(const sim::ComponentParams&) override {}
  bool SupportedBy(const sim::ModelCatalog&, const mjModel*, std::string*) const override {
    return true;
  }
  void Apply(sim::TruthSetup& s) const override {
    for (const DynamicTerm& t : terms_) {
      sim::ApplyDynamic(s, t.kind, t.location, t.values, where());
    }
  }

 private:
  std::vector<DynamicTerm> terms_;
};

// Segments before a fold rolled (not scored) before its own: the joints no encoder sees (a
// link's mode) reach the state the segments before would have carried into the fold.
constexpr int kFoldWarmUpSegments = 4;

// Commands sent before a segment's start that a delayed servo may still act on (beyond the
// largest delay a row allows).
constexpr double kCommandLookBackS = 0.25;

double StdOf(const MotionData& d, char stream) {
  const double s = d.Noise(stream);
  return s > 0.0 ? s : 1.0;
}

// The four corners of a tag seen by a camera at the simulation's state, in pixels; throws
// SimulationError when a corner is behind the camera.
std::array<Eigen::Vector2d, 4> TagCorners(const sim::Simulation& sim, const MotionCamera& cam,
                                          const MotionTag& tag) {
  const Eigen::Isometry3d T_cam_tag = sim.Pose(cam.frame).inverse() * sim.Pose(tag.frame);
  std::array<Eigen::Vector2d, 4> uv;
  for (int c = 0; c < 4; ++c) {
    if (!cam.intrinsics.Project(T_cam_tag * tag.corners_m[c], &uv[c])) {
      throw SimulationError("tag " + std::to_string(tag.id) + " is behind camera '" + cam.name +
                            "'");
    }
  }
  return uv;
}

}  // namespace

RolloutModel::RolloutModel(sim::MjModelPtr model, std::string name,
                           std::vector<DynamicTerm> declared)
    : model_(std::move(model)), name_(std::move(name)), declared_(std::move(declared)) {
  nominal_ = Make({});
}

std::unique_ptr<sim::Simulation> RolloutModel::Make(const std::vector<DynamicTerm>& terms) const {
  std::vector<DynamicTerm> all = declared_;
  all.insert(all.end(), terms.begin(), terms.end());
  sim::EffectList effects;
  if (!all.empty()) effects.push_back(std::make_unique<TermsEffect>(std::move(all)));
  sim::MjModelPtr copy(mj_copyModel(nullptr, model_.get()));
  return std::make_unique<sim::Simulation>(std::move(copy), name_, effects);
}

ResidualLayout MakeLayout(const MotionData& d) {
  ResidualLayout L;
  const int nj = static_cast<int>(d.joints.size());
  struct Entry {
    double t;
    char stream;
    int channel;
    double value;
  };
  std::vector<Entry> entries;
  for (size_t s = 0; s < d.segments.size(); ++s) {
    const Segment& g = d.segments[s];
    const double t0 = d.t[g.row_begin], t1 = d.t[g.row_end - 1];
    entries.clear();
    for (int r = g.row_begin + 1; r < g.row_end; ++r) {
      for (int k = 0; k < nj; ++k) entries.push_back({d.t[r], 0, k, d.q(r, k)});
    }
    for (size_t i = 0; i < d.imus.size(); ++i) {
      const MotionImu& imu = d.imus[i];
      const auto a = std::upper_bound(imu.t.begin(), imu.t.end(), t0) - imu.t.begin();
      for (auto r = a; r < static_cast<long>(imu.t.size()) && imu.t[r] <= t1; ++r) {
        for (int x = 0; x < 3; ++x) {
          entries.push_back({imu.t[r], 1, static_cast<int>(i) * 3 + x, imu.gyro(r, x)});
          entries.push_back({imu.t[r], 2, static_cast<int>(i) * 3 + x, imu.accel(r, x)});
        }
      }
    }
    const int nt = static_cast<int>(d.tags.size());
    const auto first_row =
        std::upper_bound(d.tag_rows.begin(), d.tag_rows.end(), t0,
                         [](double t, const MotionTagRow& r) { return t < r.t; });
    for (auto r = first_row; r != d.tag_rows.end() && r->t <= t1; ++r) {
      for (int c = 0; c < 4; ++c) {
        for (int x = 0; x < 2; ++x) {
          entries.push_back({r->t, 3, TagChannel(r->camera, r->tag, nt, c, x), r->uv[c][x]});
        }
      }
    }
    std::stable_sort(entries.begin(), entries.end(),
                     [](const Entry& a, const Entry& b) { return a.t < b.t; });
    for (const Entry& e : entries) {
      L.segment.push_back(static_cast<int>(s));
      L.stream.push_back(e.stream);
      L.channel.push_back(e.channel);
      L.t.push_back(e.t);
      L.value.push_back(e.value);
    }
  }
  return L;
}

Prediction NewPrediction(const MotionData& d, const ResidualLayout& L) {
  Prediction p;
  p.error = Eigen::VectorXd::Zero(L.size());
  p.residual = Eigen::VectorXd::Zero(L.size());
  p.diverged.assign(d.segments.size(), 0);
  return p;
}

std::string RolloutFold(const RolloutModel& model, const std::vector<DynamicTerm>& terms,
                        const MotionData& d, const ResidualLayout& L, int fold, Prediction* p,
                        const Eigen::MatrixXd* start_qd) {
  const Eigen::MatrixXd& starts = start_qd ? *start_qd : d.start_qd;
  std::unique_ptr<sim::Simulation> sim = model.Make(terms);
  const int nj = static_cast<int>(d.joints.size());
  const double dt = sim->timestep();
  const std::vector<int>& actuated = sim->catalog().actuated;
  const auto settle_at = [&](int row) {
    sim->SetCommand(d.q.row(row).transpose());
    sim->Settle();
  };
  size_t s = 0;
  while (s < d.segments.size() && d.segments[s].fold != fold) ++s;
  if (s == d.segments.size()) return "";
  // The warm-up: the segments before the fold, rolled and not scored.
  s = s > static_cast<size_t>(kFoldWarmUpSegments) ? s - kFoldWarmUpSegments : 0;
  int e = 0;
  while (e < L.size() && L.segment[e] < static_cast<int>(s)) ++e;
  std::string first_divergence;
  try {
    settle_at(d.segments[s].row_begin);
  } catch (const SimulationError& err) {
    // No state to start from: every segment of the fold is lost.
    for (; s < d.segments.size() && d.segments[s].fold <= fold; ++s) {
      if (d.segments[s].fold == fold) p->diverged[s] = 1;
    }
    return err.what();
  }
  Eigen::VectorXd q0(nj), qd0(nj), c_row(nj);
  for (; s < d.segments.size() && d.segments[s].fold <= fold; ++s) {
    const Segment& g = d.segments[s];
    const bool scored = g.fold == fold;
    const int first = e;
    while (e < L.size() && L.segment[e] == static_cast<int>(s)) ++e;
    try {
      const double t0 = d.t[g.row_begin];
      q0 = d.q.row(g.row_begin).transpose();
      qd0 = starts.row(static_cast<int>(s)).transpose();
      sim->SetActuatedState(t0, q0, qd0);
      // From the command in force at the look-back's start (the last sent before it) on.
      size_t c = std::upper_bound(d.command_t.begin(), d.command_t.end(), t0 - kCommandLookBackS) -
                 d.command_t.begin();
      if (c > 0) --c;
      const auto send_until = [&](double t) {
        for (; c < d.command_t.size() && d.command_t[c] <= t + 1e-9; ++c) {
          c_row = d.command.row(static_cast<int>(c)).transpose();
          if (d.torque) {
            sim->SetTorque(c_row);
          } else {
            sim->SetCommandAt(d.command_t[c], c_row);
          }
        }
      };
      send_until(t0);
      double imu_t = -1.0, tag_t = -1.0;
      int imu_i = -1, tag_i = -1;
      Vec3 gyro = Vec3::Zero(), accel = Vec3::Zero();
      std::array<Eigen::Vector2d, 4> corners;
      const int nt = static_cast<int>(d.tags.size());
      for (int k = first; k < e; ++k) {
        while (sim->time() < L.t[k] - 0.5 * dt) {
          send_until(sim->time());
          sim->Step(1);
        }
        // A command row is in force from its time on: readings then see it (an accelerometer
        // reads the servo's force of that instant).
        send_until(sim->time());
        if (!scored) continue;
        double pred = 0.0;
        if (L.stream[k] == 0) {
          pred = sim->JointPosition(actuated[L.channel[k]]);
        } else if (L.stream[k] == 3) {
          const int pair = TagPairOf(L.channel[k]);
          if (L.t[k] != tag_t || pair != tag_i) {
            corners = TagCorners(*sim, d.cameras[pair / nt], d.tags[pair % nt]);
            tag_t = L.t[k];
            tag_i = pair;
          }
          pred = corners[TagCornerOf(L.channel[k])][TagAxisOf(L.channel[k])];
        } else {
          const int i = L.channel[k] / 3;
          if (L.t[k] != imu_t || i != imu_i) {
            gyro = sim->SiteAngularVelocity(d.imus[i].site_id);
            accel = sim->SiteSpecificForce(d.imus[i].site_id);
            imu_t = L.t[k];
            imu_i = i;
          }
          pred = (L.stream[k] == 1 ? gyro : accel)[L.channel[k] % 3];
        }
        if (!std::isfinite(pred)) throw SimulationError("a prediction is not finite");
        p->error[k] = pred - L.value[k];
        p->residual[k] = p->error[k] / StdOf(d, L.stream[k]);
      }
    } catch (const SimulationError& err) {
      if (scored) {
        p->diverged[s] = 1;
        if (first_divergence.empty()) first_divergence = err.what();
        for (int k = first; k < e; ++k) p->error[k] = p->residual[k] = 0.0;
      }
      try {
        settle_at(g.row_end - 1);
      } catch (const SimulationError&) {
        // The next segment starts from the recorded angles whatever the unobserved joints do.
      }
    }
  }
  return first_divergence;
}

void FinishPrediction(const std::vector<std::string>& fold_divergence, Prediction* p) {
  p->num_diverged = 0;
  for (char x : p->diverged) p->num_diverged += x != 0;
  p->first_divergence.clear();
  for (const std::string& m : fold_divergence) {
    if (!m.empty()) {
      p->first_divergence = m;
      break;
    }
  }
}

Prediction Rollout(const RolloutModel& model, const std::vector<DynamicTerm>& terms,
                   const MotionData& d, const ResidualLayout& L) {
  Prediction p = NewPrediction(d, L);
  std::vector<std::string> divergence(d.folds);
  for (int f = 0; f < d.folds; ++f) divergence[f] = RolloutFold(model, terms, d, L, f, &p);
  FinishPrediction(divergence, &p);
  return p;
}

void SetUnknownNoise(const ResidualLayout& L, const Eigen::VectorXd& err, MotionData* d) {
  // Per stream and channel: consecutive entries of one channel within one segment.
  double sum[kStreams] = {0, 0, 0, 0};
  long count[kStreams] = {0, 0, 0, 0};
  std::vector<std::vector<int>> last(kStreams);
  for (auto& v : last) v.assign(64, -1);
  for (int k = 0; k < L.size(); ++k) {
    const int s = L.stream[k], c = L.channel[k];
    if (c >= static_cast<int>(last[s].size())) last[s].resize(c + 1, -1);
    const int prev = last[s][c];
    if (prev >= 0 && L.segment[prev] == L.segment[k]) {
      const double diff = err[k] - err[prev];
      sum[s] += diff * diff;
      ++count[s];
    }
    last[s][c] = k;
  }
  for (int s = 0; s < kStreams; ++s) {
    if (d->noise_from_log[s] || count[s] == 0) continue;
    double* std = d->MutableNoise(s);
    *std = std::sqrt(sum[s] / count[s] / 2.0);
    if (!(*std > 0.0)) *std = 1e-12;
  }
}

}  // namespace flexbench::identify::dynamic
