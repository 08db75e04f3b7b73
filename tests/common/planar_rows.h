// Point rows of planar3's end effector made by MuJoCo's own kinematics, not by the effect model
// under test: the truth the declared model matches, optionally with joint offsets planted
// (link angle = reading + offset) and Gaussian point noise.
#pragma once

#include <mujoco/mujoco.h>

#include <array>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {

// The CSV header of PlanarRows.
inline constexpr const char* kPlanarHeader = "joint1,joint2,joint3,x,y,z\n";

inline std::string PlanarRows(int n, std::mt19937_64& rng, double noise_std_m = 1e-4,
                              const std::array<double, 3>& offset_rad = {0.0, 0.0, 0.0}) {
  std::vector<std::string> warnings;
  sim::MjModelPtr m = sim::LoadModel(SourceDir() + "/models/planar3.xml", &warnings);
  mjData* d = mj_makeData(m.get());
  const int ee = mj_name2id(m.get(), mjOBJ_SITE, "ee");
  std::uniform_real_distribution<double> q(-1.2, 1.2);
  std::normal_distribution<double> noise(0.0, noise_std_m);
  std::string csv;
  for (int i = 0; i < n; ++i) {
    double reading[3];
    for (int j = 0; j < 3; ++j) {
      reading[j] = q(rng);
      const int jid = mj_name2id(m.get(), mjOBJ_JOINT, ("joint" + std::to_string(j + 1)).c_str());
      d->qpos[m->jnt_qposadr[jid]] = reading[j] + offset_rad[j];
    }
    mj_kinematics(m.get(), d);
    double p[3];
    for (int a = 0; a < 3; ++a) p[a] = d->site_xpos[3 * ee + a] + noise(rng);
    char row[256];
    std::snprintf(row, sizeof(row), "%.9f,%.9f,%.9f,%.9f,%.9f,%.9f\n", reading[0], reading[1],
                  reading[2], p[0], p[1], p[2]);
    csv += row;
  }
  mj_deleteData(d);
  return csv;
}

}  // namespace flexbench::testing
