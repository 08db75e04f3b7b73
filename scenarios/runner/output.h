// Results are written into a temporary folder beside the destination and moved into place only
// when the run finished, so an interrupted or failed run never leaves a half-written output.
// Nothing that is not a result is ever removed: an existing destination is replaced only when
// it is an empty folder or a previous flexbench result (it holds the result marker, or a
// summary.json with the fields every flexbench summary has), or with `force` a folder that
// holds no input of the run; a file in its place is always refused.
// Every temporary ("<final>.tmp-PID", and "<final>.old-PID" while a previous result is being
// replaced) holds a marker naming the host, the PID namespace, the PID and the start time of
// the process that made it. A later run to the same destination removes only temporaries with
// such a marker of its own host and PID namespace whose process has ended: a folder the user
// named alike, or a live run on another machine or in another container, is never touched.
// SIGTERM, SIGINT and SIGHUP (while they have their default action) remove this process's
// temporaries before the process ends by the signal.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace flexbench::scenarios {

// The file every committed result holds (fixed content), and the marker of a temporary (removed
// before the temporary becomes the result).
inline constexpr const char* kResultMarker = ".flexbench-result";
inline constexpr const char* kTemporaryMarker = ".flexbench-temporary";

// Which images a run writes (`--frames`): every rendered camera frame; the key ones (a few
// spread over the run, and every figure: what a report shows); or no image at all (a sweep's
// runs, which keep their summaries, CSVs and trajectories).
enum class FrameOutput { kAll, kKey, kNone };

// "all", "key" or "none"; anything else is InputError naming `option`.
FrameOutput ParseFrameOutput(const std::string& text, const std::string& option);
const char* FrameOutputName(FrameOutput f);

// Whether camera frame `index` of `count` is written: every one with kAll, none with kNone;
// with kKey the `key_count` frames spread evenly from the first.
bool WritesFrame(FrameOutput f, int index, int count, int key_count);

class OutputDir {
 public:
  // Creates the temporary folder (and its frames/ folder). Throws InputError naming the path
  // when the parent cannot be written or the destination may not be replaced. `inputs` are
  // files the run reads, besides every file this process accepted as an input
  // (RecordedInputFiles): a destination holding one is refused even with `force`.
  explicit OutputDir(const std::filesystem::path& final_dir, bool force = false,
                     const std::vector<std::filesystem::path>& inputs = {});
  // Removes the temporary folder unless Commit() succeeded.
  ~OutputDir();
  OutputDir(const OutputDir&) = delete;
  OutputDir& operator=(const OutputDir&) = delete;

  // Path of a file inside the (temporary) output folder; creates parent folders.
  std::filesystem::path File(const std::string& relative) const;
  std::filesystem::path FramesDir() const { return tmp_ / "frames"; }
  // Removes every PNG written so far (--frames none): one place, whichever kind drew them.
  void RemoveImages();
  // Removes every file written so far, and the folders left empty (a sweep's runs with
  // --run-files summary keep only the summary.json and report.html written after this).
  void RemoveDataFiles();

  // Replaces `final_dir` with the temporary folder (checked again, with the inputs read since:
  // refused when something that is not a result appeared there meanwhile). A signal that
  // arrives while the folders are being swapped takes effect once they are.
  void Commit();

  const std::filesystem::path& final_dir() const { return final_; }

 private:
  std::filesystem::path final_;
  std::filesystem::path tmp_;
  bool force_ = false;
  std::vector<std::filesystem::path> inputs_;
  bool committed_ = false;
  int signal_slot_ = -1;  // this temporary's entry in the signal handler's list
};

// Throws InputError unless `dir` may be replaced by a run's results (see above).
void CheckReplaceable(const std::filesystem::path& dir, bool force,
                      const std::vector<std::filesystem::path>& inputs);

// True when `dir` holds a flexbench result: the result marker, or a summary.json (a regular
// file, not a link) that parses as an object with the fields every run's summary has.
bool IsFlexbenchResult(const std::filesystem::path& dir);

// The name of the temporary ("tmp") or replaced ("old") folder of destination name `name` for
// process `pid`, attempt `k`: "<name>.tmp-PID", "<name>.tmp-PID-K" for a second folder of the
// same process; a name too long for the file system is cut and completed by a hash of the
// whole name, so that it stays within NAME_MAX.
std::string TemporaryName(const std::string& name, const char* tag, long pid, int k = 0);

// Removes the temporaries beside each of `final_dirs` of ended runs of this host (what a new
// OutputDir to one removes first). A sweep calls it for every run once its workers are done: a
// killed worker may still be dying while the resumed sweep runs its run again.
void RemoveEndedTemporaries(const std::vector<std::filesystem::path>& final_dirs);

// Writes `text` to `path` through a temporary file and a rename.
void WriteFileAtomic(const std::filesystem::path& path, const std::string& text);

}  // namespace flexbench::scenarios
