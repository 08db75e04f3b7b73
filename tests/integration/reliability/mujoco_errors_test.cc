// MuJoCo's fatal errors unwind instead of ending the process: sim::InstallMujocoHandlers makes
// mju_error throw sim::MujocoError through MuJoCo's C frames, so callers' destructors run (an
// output temporary is removed) and MuJoCo serves the next model. Visual sizes MuJoCo or OSMesa
// would fail on are refused when the model is loaded, naming the file and the attribute.
#include <gtest/gtest.h>
#include <mujoco/mujoco.h>

#include <filesystem>
#include <string>

#include "render/gl_context.h"
#include "render/renderer.h"
#include "sim/mujoco_model.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;

std::string Planar3() { return ReadFile(SourceDir() + "/models/planar3.xml"); }

// planar3.xml with `from` replaced by `to`, written to `dir`/m.xml.
fs::path ModelWith(const fs::path& dir, const std::string& from, const std::string& to) {
  std::string xml = Planar3();
  const size_t at = xml.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) xml.replace(at, from.size(), to);
  const fs::path path = dir / "m.xml";
  WriteFile(path, xml);
  return path;
}

// Anything named `out` or `out` + suffix (a temporary) beside it.
std::vector<std::string> Leftovers(const fs::path& out) {
  std::vector<std::string> found;
  for (const auto& e : fs::directory_iterator(out.parent_path())) {
    const std::string name = e.path().filename().string();
    if (name.compare(0, out.filename().string().size(), out.filename().string()) == 0) {
      found.push_back(name);
    }
  }
  return found;
}

TEST(MujocoFatalErrors, AnErrorInsideMujocoThrowsAndTheModelStillSteps) {
  sim::InstallMujocoHandlers();
  const sim::MjModelPtr m = sim::LoadModelFromString(Planar3(), "planar3.xml");
  const sim::MjDataPtr d = sim::MakeData(m.get());
  const int pstack = d->pstack;
  // mj_stackAlloc is C: its mju_error has to unwind through it.
  try {
    mj_stackAlloc(d.get(), d->nstack + 1);
    ADD_FAILURE() << "mj_stackAlloc returned";
  } catch (const sim::MujocoError& e) {
    EXPECT_EQ(std::string(e.what()).rfind("MuJoCo: ", 0), 0u) << e.what();
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
  }
  EXPECT_EQ(d->pstack, pstack);
  for (int i = 0; i < 100; ++i) mj_step(m.get(), d.get());
  EXPECT_GT(d->time, 0.19);
  const sim::MjModelPtr again = sim::LoadModelFromString(Planar3(), "again.xml");
  const sim::MjDataPtr d2 = sim::MakeData(again.get());
  mj_forward(again.get(), d2.get());
  EXPECT_TRUE(std::isfinite(d2->site_xpos[0]));
}

TEST(MujocoFatalErrors, AFailedGlContextThrowsAndTheNextRendererDraws) {
  sim::InstallMujocoHandlers();
  const sim::MjModelPtr m = sim::LoadModelFromString(Planar3(), "planar3.xml");
  const sim::MjDataPtr d = sim::MakeData(m.get());
  mj_forward(m.get(), d.get());
  // Straight to MuJoCo, past the load-time check: its shadow framebuffer cannot be made.
  render::EnsureGlContext();
  m->vis.quality.shadowsize = 60000;
  mjrContext con;
  mjr_defaultContext(&con);
  try {
    mjr_makeContext(m.get(), &con, mjFONTSCALE_100);
    ADD_FAILURE() << "mjr_makeContext returned";
  } catch (const sim::MujocoError& e) {
    EXPECT_NE(std::string(e.what()).find("hadow"), std::string::npos) << e.what();
  }
  mjr_freeContext(&con);
  for (int i = 0; i < 16 && mjr_getError() != 0; ++i) {
  }
  // The Renderer refuses the size before GL sees it...
  EXPECT_NE(ErrorOf([&] {
              render::Renderer r(m.get(), render::RenderMode::kQuality);
            }).find("shadowsize=\"60000\""),
            std::string::npos);
  // ...and with a size GL can make, the process renders as before.
  m->vis.quality.shadowsize = 2048;
  render::Renderer renderer(m.get(), render::RenderMode::kQuality);
  const render::Image frame = renderer.RenderRgb(d.get(), sim::CameraId(m.get(), "overview"));
  ASSERT_EQ(frame.width, 640);
  bool varied = false;
  for (size_t i = 3; i < frame.data.size() && !varied; ++i) varied = frame.data[i] != frame.data[0];
  EXPECT_TRUE(varied);
}

// planar3 with a pendulum that the configuration swings into the floor, and MuJoCo's stack
// just big enough to compile the model: the contacts overflow it in the run's mj_forward,
// after the output temporary exists.
std::string StackOverflowingRun(const fs::path& dir) {
  std::string xml = Planar3();
  xml.replace(xml.find("  </worldbody>"), 0,
              "    <body name=\"pendulum\" pos=\"-0.5 0 0.2\">\n"
              "      <joint name=\"swing\" type=\"hinge\" axis=\"1 0 0\"/>\n"
              "      <geom type=\"capsule\" fromto=\"0 0 0 0 0 0.4\" size=\"0.03\"/>\n"
              "    </body>\n");
  xml.replace(xml.find("<option"), 0, "<size nstack=\"120\"/>\n  ");
  WriteFile(dir / "pendulum.xml", xml);
  std::string scenario = ReadFile(SourceDir() + "/scenarios/smoke.yaml");
  scenario.replace(scenario.find("../models/planar3.xml"), 21, (dir / "pendulum.xml").string());
  scenario.replace(scenario.find("  joint3: 0.5"), 0, "  swing: 2.5\n");
  WriteFile(dir / "pendulum.yaml", scenario);
  return (dir / "pendulum.yaml").string();
}

TEST(MujocoFatalErrors, CliRunWhoseMujocoErrorsMidRunRemovesItsTemporary) {
  TempDir tmp;
  const std::string scenario = StackOverflowingRun(tmp.path());
  // The model itself is fine: it loads.
  EXPECT_EQ(ErrorOf([&] { sim::LoadModel((tmp.path() / "pendulum.xml").string()); }), "");
  const fs::path out = tmp.path() / "results";
  const CommandResult r =
      RunCommand("cd " + tmp.path().string() + " && timeout 120 " + BinDir() + "/flexbench run " +
                 scenario + " --out " + out.string() + " --quiet </dev/null");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_EQ(CountLines(r.err), 1) << r.err;
  EXPECT_EQ(LastLine(r.err), "flexbench: error: MuJoCo: Stack overflow") << r.err;
  EXPECT_TRUE(Leftovers(out).empty());
  EXPECT_FALSE(fs::exists(tmp.path() / "MUJOCO_LOG.TXT"));
}

TEST(MujocoFatalErrors, VisualSizesAreCheckedAtLoadNamingFileAndAttribute) {
  TempDir tmp;
  const std::pair<const char*, const char*> cases[] = {
      {"shadowsize=\"2048\"", "shadowsize=\"60000\""},
      {"shadowsize=\"2048\"", "shadowsize=\"-1\""},
      {"offwidth=\"640\"", "offwidth=\"0\""},
      {"shadowsize=\"2048\"", "shadowsize=\"2048\" offsamples=\"17\""}};
  for (const auto& [from, to] : cases) {
    const fs::path model = ModelWith(tmp.path(), from, to);
    const std::string attribute = std::string(to).substr(std::string(to).rfind(' ') + 1);
    const std::string name = attribute.substr(0, attribute.find('='));
    const std::string e = ErrorOf([&] { sim::LoadModel(model.string()); });
    EXPECT_EQ(e.rfind(model.string() + ": <visual>", 0), 0u) << e;
    EXPECT_NE(e.find(name), std::string::npos) << e;
  }
}

TEST(MujocoFatalErrors, CliRunAndInspectRefuseAHugeShadowMapLeavingNothing) {
  TempDir tmp;
  const fs::path model = ModelWith(tmp.path(), "shadowsize=\"2048\"", "shadowsize=\"60000\"");
  std::string scenario = ReadFile(SourceDir() + "/scenarios/smoke.yaml");
  scenario.replace(scenario.find("../models/planar3.xml"), 21, model.string());
  WriteFile(tmp.path() / "s.yaml", scenario);
  const fs::path out = tmp.path() / "results";
  const std::string fb = BinDir() + "/flexbench";
  for (const std::string& cmd :
       {fb + " run " + (tmp.path() / "s.yaml").string() + " --out " + out.string() + " --quiet",
        fb + " inspect " + model.string()}) {
    const CommandResult r =
        RunCommand("cd " + tmp.path().string() + " && timeout 120 " + cmd + " </dev/null");
    EXPECT_EQ(r.exit_code, 2) << cmd << "\n" << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_EQ(LastLine(r.err), "flexbench: error: " + model.string() +
                                   ": <visual><quality shadowsize=\"60000\">: the shadow map "
                                   "must be 0..8192 pixels (0: no shadows)")
        << r.err;
    EXPECT_TRUE(Leftovers(out).empty());
    EXPECT_FALSE(fs::exists(tmp.path() / "MUJOCO_LOG.TXT"));
  }
}

}  // namespace
}  // namespace flexbench::testing
