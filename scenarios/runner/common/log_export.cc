#include "scenarios/runner/common/log_export.h"

#include <filesystem>

#include "estimators/error.h"

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

void WriteLogsWithDeclared(const std::vector<std::pair<std::string, sim::RecordedLog>>& logs,
                           const sim::DeclaredModel& declared, const std::string& dir) {
  namespace fs = std::filesystem;
  const fs::path target = fs::absolute(dir).lexically_normal();
  const fs::path tmp = target.string() + ".tmp";
  std::error_code ec;
  if (fs::exists(target, ec) || fs::exists(tmp, ec)) {
    throw InputError(CapForMessage(dir) +
                     " or its .tmp exists; logs are written into a new folder");
  }
  fs::create_directories(tmp);
  try {
    for (const auto& [name, log] : logs) WriteLogWithDeclared(log, declared, (tmp / name).string());
    fs::rename(tmp, target);
  } catch (...) {
    fs::remove_all(tmp, ec);  // ours alone: it did not exist before
    throw;
  }
}

}  // namespace flexbench::scenarios
