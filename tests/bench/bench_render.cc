// Per-frame cost of the camera pipeline at 640x480: render + readback, detection, and both,
// in fast and quality mode. The scene is models/tag_board.xml with the tag 0.8 m from the
// camera (about 58 px wide), slightly rotated. Wall-clock time (UseRealTime): llvmpipe renders
// on worker threads, so the process's CPU time of the calling thread says little.
#include <benchmark/benchmark.h>

#include "render/renderer.h"
#include "render/tag_detector.h"
#include "render/tag_texture.h"
#include "sim/mujoco_model.h"

namespace flexbench::render {
namespace {

struct Scene {
  sim::MjModelPtr model;
  sim::MjDataPtr data;
  std::unique_ptr<Renderer> renderer;

  explicit Scene(RenderMode mode) {
    model = sim::LoadModel(std::string(FLEXBENCH_SOURCE_DIR) + "/models/tag_board.xml");
    ApplyTagTextures(model.get());
    data = sim::MakeData(model.get());
    data->mocap_quat[0] = std::cos(0.2);
    data->mocap_quat[3] = std::sin(0.2);
    mj_forward(model.get(), data.get());
    renderer = std::make_unique<Renderer>(model.get(), mode);
  }
};

RenderMode ModeOf(const benchmark::State& state) {
  return state.range(0) == 0 ? RenderMode::kFast : RenderMode::kQuality;
}

void BM_RenderReadback(benchmark::State& state) {
  Scene scene(ModeOf(state));
  Image frame;
  for (auto _ : state) {
    scene.renderer->RenderRgbInto(scene.data.get(), 0, &frame);
    benchmark::DoNotOptimize(frame.data.data());
  }
  state.SetLabel(state.range(0) == 0 ? "fast" : "quality");
}

void BM_Detect(benchmark::State& state) {
  Scene scene(ModeOf(state));
  const Image gray = ToGray(scene.renderer->RenderRgb(scene.data.get(), 0));
  TagDetector detector(DetectorSettings{});
  for (auto _ : state) {
    DetectionResult r = detector.Detect(gray);
    if (r.detections.size() != 1) state.SkipWithError("tag not detected");
    benchmark::DoNotOptimize(r);
  }
  state.SetLabel(state.range(0) == 0 ? "fast" : "quality");
}

void BM_RenderReadbackDetect(benchmark::State& state) {
  Scene scene(ModeOf(state));
  TagDetector detector(DetectorSettings{});
  Image gray;
  for (auto _ : state) {
    scene.renderer->RenderGrayInto(scene.data.get(), 0, &gray);
    DetectionResult r = detector.Detect(gray);
    if (r.detections.size() != 1) state.SkipWithError("tag not detected");
    benchmark::DoNotOptimize(r);
  }
  state.SetLabel(state.range(0) == 0 ? "fast" : "quality");
}

BENCHMARK(BM_RenderReadback)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Detect)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RenderReadbackDetect)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace flexbench::render

BENCHMARK_MAIN();
