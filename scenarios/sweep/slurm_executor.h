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
  int tasks = 0;             // array size (shards); 0: one per run, at most 64
  bool tasks_given = false;  // --tasks was on the command line (then it must be >= 1)
  std::string partition;     // passed through to sbatch when set
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

// Checks the options against Slurm's grammar before anything is written; throws InputError
// naming the option:
//   --partition  names of [A-Za-z0-9_.-], comma-separated
//   --time       MINUTES, MM:SS, HH:MM:SS, D-HH, D-HH:MM, D-HH:MM:SS (digits), or UNLIMITED
//   --mem        digits with an optional K, M, G or T suffix
//   --array      indices and ranges, comma-separated (3,5,7-9)
//   --tasks      1 to 100000 when given
void CheckSlurmOptions(const SlurmOptions& options);
// Checks that `out` can be named in an #SBATCH line: no control character (the line would
// end), no backslash (it turns off Slurm's %a). Spaces, quotes and % are fine.
void CheckSlurmOut(const std::filesystem::path& out);

// The text of <out>/slurm/job.sh for `n` array tasks; every value in it is quoted for both
// bash and sbatch's #SBATCH parser, and Slurm's % patterns in the output path are escaped.
std::string SlurmJobScript(const SweepSpec& spec, const std::filesystem::path& out,
                           const SlurmOptions& options, int n, const std::string& exe);

// Writes <out>/slurm/job.sh and submits it; returns the job id. `sweep_file` and `out` are
// made absolute so the tasks find them from any node.
std::string SubmitSlurm(const SweepSpec& spec, size_t run_count, const std::filesystem::path& out,
                        const SlurmOptions& options, int* task_count);

// Waits until the job left the queue; returns the end of every task that ran.
std::vector<SlurmTaskEnd> WaitForSlurm(const std::string& job_id, int task_count,
                                       const std::filesystem::path& out);

}  // namespace flexbench::scenarios::sweep
