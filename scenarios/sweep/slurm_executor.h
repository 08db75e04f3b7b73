// The Slurm executor: one `sbatch --array` job whose task i runs shard i/n of the sweep
// (`flexbench sweep FILE --shard i/n`), waited for with squeue, each task's end read with
// scontrol (and the exit file the task writes, for when the controller has forgotten it).
// Slurm does the scheduling; nothing here schedules.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "scenarios/sweep/sweep_file.h"

namespace flexbench::scenarios::sweep {

struct SlurmOptions {
  int tasks = 0;          // array size (shards); 0: one per run, at most 64
  std::string partition;  // passed through to sbatch when set
  std::string time;
  std::string mem;
  std::string array;  // only these task indices ("3,5"): resubmitting failed tasks
  bool wait = true;   // wait for the job and collect
};

struct SlurmTaskEnd {
  int index = 0;
  std::string state;  // COMPLETED, FAILED, TIMEOUT, ... or "unknown"
  int exit_code = -1;
};

// Throws InputError when sbatch is not on PATH.
void CheckSlurmClients();

// Writes <out>/slurm/job.sh and submits it; returns the job id. `sweep_file` and `out` are
// made absolute so the tasks find them from any node.
std::string SubmitSlurm(const SweepSpec& spec, size_t run_count, const std::filesystem::path& out,
                        const SlurmOptions& options, int* task_count);

// Waits until the job left the queue; returns the end of every task that ran.
std::vector<SlurmTaskEnd> WaitForSlurm(const std::string& job_id, int task_count,
                                       const std::filesystem::path& out);

}  // namespace flexbench::scenarios::sweep
