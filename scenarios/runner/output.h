// Results are written into a temporary folder beside the destination and moved into place only
// when the run finished, so an interrupted or failed run never leaves a half-written output.
#pragma once

#include <filesystem>
#include <string>

namespace flexbench::scenarios {

class OutputDir {
 public:
  // Creates "<final>.tmp-<pid>" (and its frames/ folder). Throws InputError naming the path
  // when the parent cannot be written.
  explicit OutputDir(const std::filesystem::path& final_dir);
  // Removes the temporary folder unless Commit() succeeded.
  ~OutputDir();
  OutputDir(const OutputDir&) = delete;
  OutputDir& operator=(const OutputDir&) = delete;

  // Path of a file inside the (temporary) output folder; creates parent folders.
  std::filesystem::path File(const std::string& relative) const;
  std::filesystem::path FramesDir() const { return tmp_ / "frames"; }

  // Replaces `final_dir` with the temporary folder.
  void Commit();

  const std::filesystem::path& final_dir() const { return final_; }

 private:
  std::filesystem::path final_;
  std::filesystem::path tmp_;
  bool committed_ = false;
};

// Writes `text` to `path` through a temporary file and a rename.
void WriteFileAtomic(const std::filesystem::path& path, const std::string& text);

}  // namespace flexbench::scenarios
