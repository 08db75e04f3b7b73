// report.html through the CLI: every run and sweep writes one, `flexbench report DIR` makes
// the same bytes again or exits 2 naming DIR, and a real headless browser (Debian's chromium)
// renders it: the screenshot is not blank and every <img> of the rendered DOM names a PNG in the
// folder that decodes.
#include <gtest/gtest.h>

#include <cstdio>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <regex>
#include <set>

#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

constexpr const char* kChromium = "/usr/bin/chromium";

CommandResult RunSmoke(const fs::path& out, const std::string& extra = "") {
  return RunCommand(Flexbench() + " run " + SourceDir() + "/scenarios/smoke.yaml --out " +
                    out.string() + " --quiet" + extra);
}

TEST(ReportCli, RunWritesReportAndReportCommandMakesTheSameBytes) {
  TempDir tmp;
  const fs::path out = tmp.path() / "r";
  const CommandResult r = RunSmoke(out, " --seed 5 --set 'render.mode=quality'");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Json s = Json::parse(ReadFile(out / "summary.json"));
  EXPECT_EQ(s["command"], Flexbench() + " run " + SourceDir() + "/scenarios/smoke.yaml --out " +
                              out.string() + " --quiet --seed 5 --set render.mode=quality");
  EXPECT_EQ(s["overrides"], Json::array({"render.mode=quality"}));
  const std::string html = ReadFile(out / "report.html");
  EXPECT_NE(html.find("--set render.mode=quality"), std::string::npos);
  EXPECT_NE(html.find("<td class=\"verdict\">PASS</td>"), std::string::npos);
  EXPECT_NE(html.find("<img src=\"frames/smoke.png\""), std::string::npos);
  EXPECT_NE(html.find("<a href=\"corners.csv\">"), std::string::npos);
  for (const auto& e : fs::directory_iterator(tmp.path())) {
    EXPECT_EQ(e.path().filename(), "r") << "left behind: " << e.path();
  }

  fs::remove(out / "report.html");
  const CommandResult again = RunCommand(Flexbench() + " report " + out.string());
  ASSERT_EQ(again.exit_code, 0) << again.err;
  EXPECT_EQ(ReadFile(out / "report.html"), html);
  // Over an existing report too (it is not listed in itself).
  ASSERT_EQ(RunCommand(Flexbench() + " report " + out.string()).exit_code, 0);
  EXPECT_EQ(ReadFile(out / "report.html"), html);
}

TEST(ReportCli, NotAResultExitsTwoWithOneLineNamingTheFolder) {
  TempDir tmp;
  const fs::path empty = tmp.path() / "empty";
  fs::create_directories(empty);
  for (const fs::path& dir : {empty, tmp.path() / "absent"}) {
    const CommandResult r = RunCommand(Flexbench() + " report " + dir.string());
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_EQ(CountLines(r.err), 1) << r.err;
    EXPECT_NE(r.err.find(dir.string()), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(dir / "report.html"));
  }
  EXPECT_EQ(RunCommand(Flexbench() + " report").exit_code, 2);
}

TEST(ReportCli, SweepWritesReportWithAggregatesAndRunLinks) {
  TempDir tmp;
  const fs::path file = tmp.path() / "s.yaml";
  WriteFile(file, "sweep: report_test\nscenario: " + SourceDir() +
                      "/scenarios/humanoid_table_contact.yaml\nseeds: {from: 1, to: 3}\n"
                      "grid:\n  distance_std_m: [0.001, 0.002]\n"
                      "plot: {metrics: [estimators.ppoe_ekf.metrics.pos_err_final_m]}\n");
  const fs::path out = tmp.path() / "sw";
  const CommandResult r = RunCommand(Flexbench() + " sweep " + file.string() + " --out " +
                                     out.string() + " -j 2 </dev/null");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string html = ReadFile(out / "report.html");
  EXPECT_NE(html.find("<h1>Sweep report_test</h1>"), std::string::npos);
  EXPECT_NE(html.find("<img src=\"sweep.png\""), std::string::npos);
  EXPECT_NE(html.find("estimators.ppoe_ekf.metrics.pos_err_final_m"), std::string::npos);
  EXPECT_NE(html.find("95% Wilson interval"), std::string::npos);
  EXPECT_NE(html.find(" sweep " + file.string() + " --out " + out.string()), std::string::npos);
  const Json agg = Json::parse(ReadFile(out / "aggregate.json"));
  for (const Json& p : agg["points"]) {
    const std::string run = "runs/" + p["point"].get<std::string>() + "/seed_1/report.html";
    EXPECT_TRUE(fs::exists(out / run)) << run;
    EXPECT_NE(html.find("href=\"" + run + "\""), std::string::npos) << run;
  }
  fs::remove(out / "report.html");
  ASSERT_EQ(RunCommand(Flexbench() + " report " + out.string()).exit_code, 0);
  EXPECT_EQ(ReadFile(out / "report.html"), html);
}

std::string G6(double v) {
  char b[32];
  std::snprintf(b, sizeof(b), "%.6g", v);
  return b;
}

// A real closed_loop run: its page holds every fitted value, its std and its unit as
// summary.json stores them, and links the calibrated model, which MuJoCo loads.
TEST(ReportCli, IdentifyRunPageHoldsTheFittedValuesTheirStdsAndUnits) {
  TempDir tmp;
  const fs::path out = tmp.path() / "cl";
  const CommandResult r =
      RunCommand(Flexbench() + " run " + SourceDir() +
                 "/scenarios/closed_loop_encoder_offset.yaml --quiet --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Json s = Json::parse(ReadFile(out / "summary.json"));
  const std::string html = ReadFile(out / "report.html");
  ASSERT_FALSE(s["identification"]["effects"].empty());
  for (const Json& e : s["identification"]["effects"]) {
    for (size_t i = 0; i < e["value"].size(); ++i) {
      const std::string cell = G6(e["value"][i].get<double>()) + " &plusmn; " +
                               G6(e["std"][i].get<double>()) + " " + e["unit"].get<std::string>();
      EXPECT_NE(html.find(cell), std::string::npos) << cell;
    }
  }
  EXPECT_NE(html.find("Verdict: <b>" + s["metrics"]["verdict"].get<std::string>() + "</b>"),
            std::string::npos);
  EXPECT_NE(html.find(G6(1e3 * s["metrics"]["val_err_before_m"].get<double>()).substr(0, 4)),
            std::string::npos);
  const Json& cm = s["identification"]["calibrated_model"];
  ASSERT_EQ(cm["mjcf"], "calibrated_model.xml") << cm.dump();
  EXPECT_NE(html.find("<a href=\"calibrated_model.xml\">"), std::string::npos);
  EXPECT_NE(html.find("<a href=\"calibrated_model.urdf\">"), std::string::npos);
  // MuJoCo's own loader takes the MJCF (inspect is mj_loadXML and the model's summary).
  const CommandResult load =
      RunCommand(Flexbench() + " inspect " + (out / "calibrated_model.xml").string());
  EXPECT_EQ(load.exit_code, 0) << load.err;
  EXPECT_NE(load.out.find("\"name\": \"rover_arm\""), std::string::npos) << load.out;
}

// --- The real browser ------------------------------------------------------------------------

std::string PercentDecode(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size()) {
      out += static_cast<char>(std::stoi(s.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += s[i];
    }
  }
  return out;
}

// Chromium renders `html`: its screenshot is not blank, and every <img> in the DOM it built
// names a file beside the page that decodes as an image. Returns the number of images.
int ExpectRendersInChromium(const fs::path& html, const fs::path& screenshot) {
  const std::string common = std::string("timeout 90 ") + kChromium +
                             " --headless --no-sandbox --disable-gpu --hide-scrollbars "
                             "--window-size=1200,2000 ";
  const std::string url = "file://" + fs::absolute(html).string();
  CommandResult r = RunCommand(common + "--screenshot=" + screenshot.string() + " " + url);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const cv::Mat shot = cv::imread(screenshot.string(), cv::IMREAD_GRAYSCALE);
  EXPECT_FALSE(shot.empty()) << "no screenshot: " << r.err;
  if (!shot.empty()) {
    EXPECT_EQ(shot.cols, 1200);
    cv::Scalar mean, stddev;
    cv::meanStdDev(shot, mean, stddev);
    EXPECT_GT(stddev[0], 20.0) << "the page looks blank (mean " << mean[0] << ")";
  }
  r = RunCommand(common + "--dump-dom " + url);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("<table"), std::string::npos) << r.out.substr(0, 2000);
  const std::regex img_src("<img[^>]*\\ssrc=\"([^\"]*)\"");
  int images = 0;
  for (std::sregex_iterator it(r.out.begin(), r.out.end(), img_src), end; it != end; ++it) {
    const std::string src = (*it)[1];
    EXPECT_EQ(src.find(':'), std::string::npos) << "not a relative path: " << src;
    const fs::path file = html.parent_path() / PercentDecode(src);
    EXPECT_TRUE(fs::is_regular_file(file)) << "broken image: " << src;
    EXPECT_FALSE(cv::imread(file.string()).empty()) << "does not decode: " << src;
    ++images;
  }
  return images;
}

int CountPngs(const fs::path& dir, bool recursive) {
  int n = 0;
  for (fs::recursive_directory_iterator it(dir), end; it != end; ++it) {
    if (!recursive && it.depth() > 0) continue;
    n += it->is_regular_file() && it->path().extension() == ".png";
  }
  return n;
}

TEST(ReportBrowser, ChromiumRendersARunsReportWithEveryImage) {
  if (!fs::exists(kChromium))
    GTEST_SKIP() << kChromium << " is not installed (apt install chromium)";
  TempDir tmp;
  const fs::path out = tmp.path() / "run";
  // Several figures and trajectories: the hand-angle experiment's report.
  const CommandResult r =
      RunCommand(Flexbench() + " run " + SourceDir() +
                 "/scenarios/rover_apriltag_exp1.yaml --quiet --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const int pngs = CountPngs(out, true);
  ASSERT_GT(pngs, 1);
  EXPECT_EQ(ExpectRendersInChromium(out / "report.html", tmp.path() / "run.png"), pngs);
  // Kept for a look by eye when FLEXBENCH_REPORT_SCREENSHOT names a file.
  if (const char* keep = std::getenv("FLEXBENCH_REPORT_SCREENSHOT")) {
    fs::copy_file(tmp.path() / "run.png", keep, fs::copy_options::overwrite_existing);
  }
}

TEST(ReportBrowser, ChromiumRendersASweepsReport) {
  if (!fs::exists(kChromium))
    GTEST_SKIP() << kChromium << " is not installed (apt install chromium)";
  TempDir tmp;
  const fs::path file = tmp.path() / "s.yaml";
  WriteFile(file, "sweep: browser_test\nscenario: " + SourceDir() +
                      "/scenarios/humanoid_table_contact.yaml\nseeds: {from: 1, to: 3}\n"
                      "plot: {metrics: [estimators.ppoe_ekf.metrics.pos_err_final_m]}\n");
  const fs::path out = tmp.path() / "sw";
  const CommandResult r = RunCommand(Flexbench() + " sweep " + file.string() + " --out " +
                                     out.string() + " -j 2 </dev/null");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(ExpectRendersInChromium(out / "report.html", tmp.path() / "sweep.png"),
            CountPngs(out, false));
  if (const char* keep = std::getenv("FLEXBENCH_SWEEP_REPORT_SCREENSHOT")) {
    fs::copy_file(tmp.path() / "sweep.png", keep, fs::copy_options::overwrite_existing);
  }
}

}  // namespace
}  // namespace flexbench::testing
