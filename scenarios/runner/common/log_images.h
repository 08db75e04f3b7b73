// A recorded log's camera frames (images/<camera>/<t_ns>.png, sim/recorded_log.h) through the
// project's libapriltag pipeline: the tags the log names become its tag rows, as if it had
// carried tags.csv.
#pragma once

#include "render/tag_detector.h"
#include "sim/recorded_log.h"

namespace flexbench::scenarios {

// Detects the tags in every frame of log->images (InputError naming a file that is no PNG or
// not of its camera's size) with `settings` (those the frames were made for: the log does not
// record them) and
// appends a tag row per detection of a tag in log->tags (others are counted, not kept); sets
// log->tag_stats (rows: the detections kept). Returns the detections of other tags.
int DetectLogImages(const render::DetectorSettings& settings, sim::RecordedLog* log);

}  // namespace flexbench::scenarios
