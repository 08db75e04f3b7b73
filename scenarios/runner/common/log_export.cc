#include "scenarios/runner/common/log_export.h"

#include <filesystem>

namespace flexbench::scenarios {

sim::RecordedLog LogOfChain(const sim::DeclaredModel& declared, const sim::DeclaredChain& chain) {
  sim::RecordedLog log;
  log.robot = std::filesystem::path(declared.model_path).stem().string();
  log.declared_path = "declared.yaml";
  const kinematics::PpoeModel& model = chain.model;
  log.joints = chain.q_joints;
  for (int k = 0; k < model.nq(); ++k) {
    log.joint_is_slide.push_back(model.frame(model.joint_frame(k)).joint.type ==
                                 kinematics::JointType::kPrismatic);
  }
  log.truth_frame = declared.end_effector;
  return log;
}

void AddStepToLog(const estimators::JointReading& joints, const lie::SE3& T_base_ee,
                  sim::RecordedLog* log) {
  log->joint_t.push_back(joints.t);
  for (int j = 0; j < joints.q.size(); ++j) log->joint_q.push_back(joints.q[j]);
  log->truth_t.push_back(joints.t);
  log->truth.push_back(T_base_ee);
}

void WriteLogWithDeclared(const sim::RecordedLog& log, const sim::DeclaredModel& declared,
                          const std::string& dir,
                          std::vector<std::pair<std::string, std::string>> files) {
  sim::DeclaredModel d = declared;
  d.model_path = std::filesystem::absolute(d.model_path).lexically_normal().string();
  files.emplace_back("declared.yaml",
                     sim::EmitDeclaredModel(d, "The declared model of the run.", 17));
  sim::WriteRecordedLog(log, dir, files);
}

}  // namespace flexbench::scenarios
