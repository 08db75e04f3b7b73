// Results are written into a temporary folder beside the destination and moved into place only
// when the run finished, so an interrupted or failed run never leaves a half-written output.
// Nothing that is not a result is ever removed: an existing destination is replaced only when
// it is an empty folder or a previous flexbench result (it holds summary.json), or with
// `force` a folder that holds no input of the run; a file in its place is always refused.
// Temporaries of killed runs ("<final>.tmp-PID", "<final>.old-PID" whose process is gone) are
// removed by the next run to the same destination.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace flexbench::scenarios {

class OutputDir {
 public:
  // Creates "<final>.tmp-<pid>" (and its frames/ folder). Throws InputError naming the path
  // when the parent cannot be written or the destination may not be replaced. `inputs` are
  // files the run reads: a destination holding one is refused even with `force`.
  explicit OutputDir(const std::filesystem::path& final_dir, bool force = false,
                     const std::vector<std::filesystem::path>& inputs = {});
  // Removes the temporary folder unless Commit() succeeded.
  ~OutputDir();
  OutputDir(const OutputDir&) = delete;
  OutputDir& operator=(const OutputDir&) = delete;

  // Path of a file inside the (temporary) output folder; creates parent folders.
  std::filesystem::path File(const std::string& relative) const;
  std::filesystem::path FramesDir() const { return tmp_ / "frames"; }

  // Replaces `final_dir` with the temporary folder (checked again: refused when something
  // that is not a result appeared there meanwhile).
  void Commit();

  const std::filesystem::path& final_dir() const { return final_; }

 private:
  std::filesystem::path final_;
  std::filesystem::path tmp_;
  bool force_ = false;
  std::vector<std::filesystem::path> inputs_;
  bool committed_ = false;
};

// Throws InputError unless `dir` may be replaced by a run's results (see above).
void CheckReplaceable(const std::filesystem::path& dir, bool force,
                      const std::vector<std::filesystem::path>& inputs);

// Writes `text` to `path` through a temporary file and a rename.
void WriteFileAtomic(const std::filesystem::path& path, const std::string& text);

}  // namespace flexbench::scenarios
