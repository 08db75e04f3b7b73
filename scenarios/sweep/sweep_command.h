// `flexbench sweep SWEEP.yaml`: expand, run (locally or on Slurm), collect, gate.
#pragma once

#include <string>

#include "scenarios/sweep/slurm_executor.h"

namespace flexbench::scenarios::sweep {

struct SweepCliOptions {
  std::string sweep_path;
  std::string out_dir;  // default: out/sweeps/<sweep name>
  int jobs = 0;         // local workers; 0: the number of cores
  std::string executor = "local";
  std::string shard;      // "i/n": run only shard i of n (what a Slurm task does), no collect
  std::string run_files;  // --run-files all|summary (empty: the sweep file's run_files)
  bool collect = false;   // only merge the runs already in the folder
  SlurmOptions slurm;
  std::string command;  // the command line as typed: recorded beside aggregate.json
};

// Exit codes: 0; 2 bad input; 3 a sweep gate failed; 1 runs failed or are missing (listed).
int SweepCommand(const SweepCliOptions& options);

}  // namespace flexbench::scenarios::sweep
