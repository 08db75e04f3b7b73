// report.html from hand-made result folders: every string from a file escaped, the gate table,
// a figure per PNG, links to the data files, deterministic bytes, InputError without a result.
#include "scenarios/runner/report.h"

#include <gtest/gtest.h>

#include <string>

#include "estimators/error.h"
#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;
using scenarios::HtmlEscape;
using scenarios::RenderReport;

int Count(const std::string& text, const std::string& what) {
  int n = 0;
  for (size_t p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

// A run folder with markup in every string a file gives the report.
void MakeRunFolder(const fs::path& dir) {
  WriteFile(dir / "summary.json", R"json({
  "scenario": "<b>x&y</b>",
  "kind": "smoke",
  "description": "a \"quoted\" <i>description</i>",
  "seed": 7,
  "command": "flexbench run 'it''s.yaml' --set 'a=<1>'",
  "overrides": ["a=<1>"],
  "metrics": {"rmse_px": 0.5, "nested": {"k": 1}, "label": "<script>alert(1)</script>",
              "series": [1, 2, 3], "missing": null},
  "estimators": {"ekf": {"metrics": {"pos_err_m": 0.01}, "updates": {"accepted": 3}},
                 "pf<1>": {"metrics": {"pos_err_m": 0.02, "ess": 100}}},
  "gates": [
    {"name": "g1", "metric": "rmse_px", "op": "<", "threshold": 1.0, "value": 0.5,
     "passed": true},
    {"name": "g<2>", "metric": "nested.k", "op": ">=", "threshold": 2.0, "value": 1.0,
     "passed": false}],
  "timing": {"total_s": 1.25}
})json");
  WriteFile(dir / "frames" / "a.png", "png");
  WriteFile(dir / "frames" / "b c#1.png", "png");
  WriteFile(dir / "plot.png", "png");
  WriteFile(dir / "data.csv", "a,b\n1,2\n");
  WriteFile(dir / "trajectories" / "base" / "truth.tum", "0 0 0 0 0 0 0 1\n");
  WriteFile(dir / "trajectories" / "base" / "ekf.tum", "0 0 0 0 0 0 0 1\n");
  WriteFile(dir / ".hidden.csv", "x\n");
  WriteFile(dir / "blob.bin", "x");
}

TEST(Report, EscapesEveryStringFromTheFiles) {
  TempDir tmp;
  MakeRunFolder(tmp.path());
  const std::string html = RenderReport(tmp.path());
  EXPECT_EQ(html.find("<b>x"), std::string::npos);
  EXPECT_EQ(html.find("<script"), std::string::npos);
  EXPECT_EQ(html.find("<i>description"), std::string::npos);
  EXPECT_NE(html.find("<h1>&lt;b&gt;x&amp;y&lt;/b&gt;</h1>"), std::string::npos);
  EXPECT_NE(html.find("&lt;script&gt;alert(1)&lt;/script&gt;"), std::string::npos);
  EXPECT_NE(html.find("a &quot;quoted&quot; &lt;i&gt;"), std::string::npos);
  EXPECT_NE(html.find("flexbench run &#39;it&#39;&#39;s.yaml&#39; --set &#39;a=&lt;1&gt;&#39;"),
            std::string::npos);
  EXPECT_NE(html.find("--set a=&lt;1&gt;"), std::string::npos);  // the overrides
  EXPECT_NE(html.find("<th>pf&lt;1&gt;</th>"), std::string::npos);
  // Self-contained: no script, nothing fetched from the network.
  EXPECT_EQ(html.find("<script"), std::string::npos);
  EXPECT_EQ(html.find("http://"), std::string::npos);
  EXPECT_EQ(html.find("https://"), std::string::npos);
  EXPECT_EQ(html.find("<link"), std::string::npos);
}

TEST(Report, GateTableHoldsVerdictValueAndThreshold) {
  TempDir tmp;
  MakeRunFolder(tmp.path());
  const std::string html = RenderReport(tmp.path());
  EXPECT_NE(html.find("1 of 2 gates passed."), std::string::npos);
  EXPECT_EQ(Count(html, "<tr class=\"pass\">"), 1);
  EXPECT_EQ(Count(html, "<tr class=\"fail\">"), 1);
  EXPECT_NE(html.find("<tr class=\"pass\"><td>g1</td><td>rmse_px</td><td class=\"num\">0.5</td>"
                      "<td>&lt;</td><td class=\"num\">1</td><td class=\"verdict\">PASS</td>"),
            std::string::npos)
      << html;
  EXPECT_NE(html.find("<tr class=\"fail\"><td>g&lt;2&gt;</td><td>nested.k</td>"
                      "<td class=\"num\">1</td><td>&gt;=</td><td class=\"num\">2</td>"
                      "<td class=\"verdict\">FAIL</td>"),
            std::string::npos);
}

TEST(Report, MetricsAreTables) {
  TempDir tmp;
  MakeRunFolder(tmp.path());
  const std::string html = RenderReport(tmp.path());
  EXPECT_NE(html.find("<tr><td>rmse_px</td><td class=\"num\">0.5</td></tr>"), std::string::npos);
  EXPECT_NE(html.find("<tr><td>nested.k</td><td class=\"num\">1</td></tr>"), std::string::npos);
  EXPECT_NE(html.find("<tr><td>series</td><td>[1, 2, 3]</td></tr>"), std::string::npos);
  EXPECT_NE(html.find("<tr><td>missing</td><td class=\"num\">&mdash;</td></tr>"),
            std::string::npos);
  // Estimators side by side; a metric one lacks is an empty cell.
  EXPECT_NE(html.find("<tr><td>pos_err_m</td><td class=\"num\">0.01</td>"
                      "<td class=\"num\">0.02</td></tr>"),
            std::string::npos);
  EXPECT_NE(html.find("<tr><td>ess</td><td></td><td class=\"num\">100</td></tr>"),
            std::string::npos);
  // Only the common "metrics." level is left out of the row names.
  EXPECT_NE(html.find("<tr><td>updates.accepted</td><td class=\"num\">3</td><td></td></tr>"),
            std::string::npos);
  // Wall-clock timing is not a result: the page is the same for every run of a seed.
  EXPECT_EQ(html.find("total_s"), std::string::npos);
}

TEST(Report, EveryPngIsAFigureAndDataFilesAreLinked) {
  TempDir tmp;
  MakeRunFolder(tmp.path());
  const std::string html = RenderReport(tmp.path());
  EXPECT_EQ(Count(html, "<figure>"), 3);
  EXPECT_EQ(Count(html, "<img "), 3);
  for (const char* src : {"frames/a.png", "frames/b%20c%231.png", "plot.png"}) {
    EXPECT_NE(html.find(std::string("<img src=\"") + src + "\""), std::string::npos) << src;
  }
  EXPECT_NE(html.find("<figcaption>Figure 2: <code>frames/b c#1.png</code>"), std::string::npos);
  for (const char* file :
       {"data.csv", "summary.json", "trajectories/base/ekf.tum", "trajectories/base/truth.tum"}) {
    EXPECT_NE(html.find(std::string("<a href=\"") + file + "\">" + file + "</a>"),
              std::string::npos)
        << file;
  }
  EXPECT_EQ(html.find(".hidden.csv"), std::string::npos);
  EXPECT_EQ(html.find("blob.bin"), std::string::npos);
}

TEST(Report, SameFolderSameBytesAndTheReportIsNotListed) {
  TempDir tmp;
  MakeRunFolder(tmp.path());
  const std::string first = RenderReport(tmp.path());
  // Timing of another length (so another summary.json size) gives the same page.
  std::string summary = ReadFile(tmp.path() / "summary.json");
  summary.replace(summary.find("1.25"), 4, "1.2345678");
  WriteFile(tmp.path() / "summary.json", summary);
  EXPECT_EQ(RenderReport(tmp.path()), first);
  scenarios::WriteReport(tmp.path());
  EXPECT_EQ(ReadFile(tmp.path() / "report.html"), first);
  EXPECT_EQ(RenderReport(tmp.path()), first);
  EXPECT_FALSE(fs::exists(tmp.path() / "report.html.part"));
}

TEST(Report, ResultsInsideARunGetTheirOwnReportLinkedFromTheRuns) {
  TempDir tmp;
  MakeRunFolder(tmp.path());
  WriteFile(tmp.path() / "identify" / "summary.json",
            R"json({"scenario": "identify", "seed": 0, "metrics": {"x": 1}})json");
  WriteFile(tmp.path() / "identify" / "fit.png", "png");
  scenarios::WriteReport(tmp.path());
  const std::string inner = ReadFile(tmp.path() / "identify" / "report.html");
  EXPECT_NE(inner.find("<h1>identify</h1>"), std::string::npos);
  EXPECT_NE(inner.find("<img src=\"fit.png\""), std::string::npos);
  const std::string outer = ReadFile(tmp.path() / "report.html");
  EXPECT_NE(outer.find("<a href=\"identify/report.html\">"), std::string::npos);
  EXPECT_NE(outer.find("<img src=\"identify/fit.png\""), std::string::npos);
}

TEST(Report, FolderWithoutResultIsInputError) {
  TempDir tmp;
  WriteFile(tmp.path() / "data.csv", "a\n");
  try {
    RenderReport(tmp.path());
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(tmp.path().string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("not a flexbench result"), std::string::npos);
  }
  WriteFile(tmp.path() / "summary.json", "{not json");
  EXPECT_THROW(RenderReport(tmp.path()), InputError);
  EXPECT_THROW(RenderReport(tmp.path() / "absent"), InputError);
}

TEST(Report, SweepHasAggregateTablesGatePassFractionsAndPlots) {
  TempDir tmp;
  WriteFile(tmp.path() / "aggregate.json", R"json({
  "sweep": "s<1>", "seeds": [1, 2, 3, 5], "runs": 4, "succeeded": 4, "failed": [],
  "bootstrap_resamples": 2000,
  "points": [{"point": "base", "set": {"noise": "0.1"}, "runs": 4, "succeeded": 4,
    "metrics": {"err_m": {"n": 4, "mean": 0.25, "std": 0.1, "median": 0.2, "min": 0.1,
                          "max": 0.4, "ci_low": 0.15, "ci_high": 0.35}},
    "gates": {"g": {"passes": 3, "n": 4, "pass_fraction": 0.75, "wilson_low": 0.3,
                    "wilson_high": 0.95}}}],
  "gates": [{"name": "mean_err", "metric": "mean(err_m)", "op": "<", "point": "base",
             "threshold": 0.3, "value": 0.25, "passed": true}],
  "gates_passed": true
})json");
  WriteFile(tmp.path() / "sweep_command.json",
            R"json({"command": "flexbench sweep s.yaml --out x", "sweep_file": "s.yaml",
                "scenario": "a.yaml"})json");
  WriteFile(tmp.path() / "sweep.csv", "point,seed\n");
  WriteFile(tmp.path() / "sweep.png", "png");
  WriteFile(tmp.path() / "runs" / "base" / "seed_1" / "summary.json", "{}");
  WriteFile(tmp.path() / "runs" / "base" / "seed_1" / "report.html", "<html></html>");
  WriteFile(tmp.path() / "runs" / "base" / "seed_1" / "data.csv", "a\n");
  WriteFile(tmp.path() / "runs" / "base" / "seed_1" / "frames" / "f.png", "png");
  const std::string html = RenderReport(tmp.path());
  EXPECT_NE(html.find("<h1>Sweep s&lt;1&gt;</h1>"), std::string::npos);
  EXPECT_NE(html.find("1&ndash;3, 5 (4 seeds)"), std::string::npos);
  EXPECT_NE(html.find("flexbench sweep s.yaml --out x"), std::string::npos);
  EXPECT_NE(html.find("<tr><td>err_m</td><td class=\"num\">4</td><td class=\"num\">0.25</td>"
                      "<td class=\"num\">[0.15, 0.35]</td>"),
            std::string::npos)
      << html;
  EXPECT_NE(html.find("<tr><td>g</td><td class=\"num\">3 / 4</td><td class=\"num\">0.75</td>"
                      "<td class=\"num\">[0.3, 0.95]</td></tr>"),
            std::string::npos);
  EXPECT_NE(html.find("1 of 1 gates passed."), std::string::npos);
  EXPECT_NE(html.find("<code>noise=0.1</code>"), std::string::npos);
  // The sweep's own plots; the runs' figures are in the runs' reports, linked.
  EXPECT_EQ(Count(html, "<img "), 1);
  EXPECT_NE(html.find("<img src=\"sweep.png\""), std::string::npos);
  EXPECT_NE(html.find("href=\"runs/base/seed_1/report.html\""), std::string::npos);
  EXPECT_NE(html.find("href=\"runs/base/seed_1/summary.json\""), std::string::npos);
  EXPECT_EQ(html.find("runs/base/seed_1/data.csv"), std::string::npos);
  EXPECT_NE(html.find("href=\"sweep.csv\""), std::string::npos);
}

// An identification's summary.json as closed_loop writes it (keys of
// scenarios/runner/kinds/closed_loop.cc), with a two-parameter effect and an also-fits entry.
void MakeIdentifyFolder(const fs::path& dir, const std::string& extra = "") {
  WriteFile(dir / "summary.json", R"json({
  "scenario": "closed_loop_encoder_offset", "kind": "closed_loop", "seed": 11,
  "metrics": {"verdict": "ambiguous", "val_err_before_m": 0.0016243554508408508,
              "val_err_after_m": 6.532768333128384e-05, "cal_err_before_m": 0.0017948,
              "cal_err_after_m": 6.144e-05, "cv_err_before": 123.09, "cv_err_after": 0.16409,
              "truth_effects": ["joint_offset@j3"], "effect_found_correct": true,
              "nees_before": 0.19, "nees_after": 0.0087, "nees_bound_low": 2.29,
              "nees_bound_high": 3.65, "source_covariance_scale": 1e-06,
              "nees_after_scaled": 0.466, "cal_residual_noise_ratio": 0.417,
              "unidentifiable": ["joint_offset@j1", "link_length@j2"],
              "residual_finding": {"significant": false,
                "message": "residual periodic in j3, 1 cycles/rev, 0.0163 deg, p = 0.074"}},
  "identification": {
    "effects": [
      {"effect": "joint_offset@j3", "value": [-0.005241138332355449],
       "std": [1.1931675845693566e-05], "unit": "rad", "share": 0.954},
      {"effect": "base_compliance@base_plate", "value": [0.000285681, 0.000768366],
       "std": [1.92586e-05, 6.42205e-06], "unit": "rad/Nm", "share": 0.0457}],
    "alternatives": [
      {"banned": "joint_offset@j3", "effects": ["link_offset@j4", "joint_axis_tilt_b@j4"],
       "cv_err": 0.16703}],
    "also_fits": [
      {"banned": "base_compliance@base_plate", "effects": ["link_bending@j2", "backlash@j2"],
       "num_params": 2, "chosen_num_params": 1, "cv_err": 0.17}],
    "equivalence_sets": [], "simpler_equivalents": []},
  "gates": [{"name": "g", "metric": "val_err_after_m", "op": "<", "threshold": 1,
             "value": 6.5e-05, "passed": true}]
  )json" + extra + "}");
}

TEST(Report, IdentificationPageAnswersFirstWithValuesStdsAndUnits) {
  TempDir tmp;
  MakeIdentifyFolder(tmp.path());
  WriteFile(tmp.path() / "declared_augmented.yaml", "model: m.xml\n");
  WriteFile(tmp.path() / "calibrated_model.xml", "<mujoco/>\n");
  const std::string html = RenderReport(tmp.path());
  // Every fitted value with its std and unit, as stored and in readable units.
  EXPECT_NE(html.find("-0.00524114 &plusmn; 1.19317e-05 rad"), std::string::npos) << html;
  EXPECT_NE(html.find("-0.3003 &plusmn; 0.00068 deg"), std::string::npos);
  EXPECT_NE(html.find("0.000285681 &plusmn; 1.92586e-05 rad/Nm<br>0.000768366 &plusmn; "
                      "6.42205e-06 rad/Nm"),
            std::string::npos);
  EXPECT_NE(html.find("<td class=\"num\">439</td>"), std::string::npos);  // |value| / std
  // In view above the effects however many there are: their count and the held-out error.
  EXPECT_NE(html.find("<p>2 effects found (3 parameters); the held-out error goes from 1.624 mm "
                      "to 0.06533 mm (0.0402 of it).</p>"),
            std::string::npos);
  // The verdict in words; held-out error before and after in mm.
  EXPECT_NE(html.find("Verdict: <b>ambiguous</b> &mdash; the correction holds"), std::string::npos);
  EXPECT_NE(html.find("<td class=\"num\">1.624 mm</td><td class=\"num\">0.06533 mm</td>"),
            std::string::npos);
  // How sure and what is left: the alternative, the more complex fit, the NEES explained.
  EXPECT_NE(html.find("<code>link_offset@j4 + joint_axis_tilt_b@j4</code> reach a held-out "
                      "error of 0.167"),
            std::string::npos);
  EXPECT_NE(html.find("with 2 parameters instead of 1"), std::string::npos);
  EXPECT_NE(html.find("0.0087 under the identified one"), std::string::npos);
  EXPECT_NE(html.find("below it, the declared sources are larger than the error left"),
            std::string::npos);
  EXPECT_NE(html.find("residual periodic in j3, 1 cycles/rev"), std::string::npos);
  EXPECT_NE(html.find("2 candidates this data cannot identify"), std::string::npos);
  // The calibrated model's files, linked; the URDF the folder lacks is not.
  EXPECT_NE(html.find("<a href=\"calibrated_model.xml\">"), std::string::npos);
  EXPECT_NE(html.find("<a href=\"declared_augmented.yaml\">"), std::string::npos);
  EXPECT_EQ(html.find("<a href=\"calibrated_model.urdf\">"), std::string::npos);
  // Above the rest: the answer before the run's table, gates and the (folded) metrics.
  const size_t answer = html.find("<h2>The answer</h2>");
  ASSERT_NE(answer, std::string::npos);
  EXPECT_LT(answer, html.find("<h2>How this was made</h2>"));
  EXPECT_LT(answer, html.find("<h2>Gates</h2>"));
  EXPECT_LT(html.find("<h2>Metrics</h2>\n<details>"), html.find("<tr><td>val_err_before_m</td>"));
}

TEST(Report, RunWithoutIdentificationHasNoAnswerAndUnfoldedMetrics) {
  TempDir tmp;
  MakeRunFolder(tmp.path());
  const std::string html = RenderReport(tmp.path());
  EXPECT_EQ(html.find("The answer"), std::string::npos);
  EXPECT_EQ(html.find("<details>"), std::string::npos);
  EXPECT_EQ(html.find("class=\"warnings\""), std::string::npos);
}

TEST(Report, WarningsComeFirstEscaped) {
  TempDir tmp;
  MakeIdentifyFolder(tmp.path(), R"json(, "warnings": ["sources scaled <outside> the fit's data",
      "second"])json");
  WriteFile(tmp.path() / "identify" / "summary.json",
            R"json({"scenario": "identify", "warnings": ["inner one"]})json");
  const std::string html = RenderReport(tmp.path());
  const size_t box = html.find("<div class=\"warnings\">");
  ASSERT_NE(box, std::string::npos) << html;
  EXPECT_LT(box, html.find("<h2>The answer</h2>"));
  EXPECT_NE(html.find("<li>sources scaled &lt;outside&gt; the fit&#39;s data</li>\n<li>second</li>"
                      "\n<li>identify/: inner one</li>"),
            std::string::npos);
}

TEST(Report, EstimatorsBeforeAndAfterInMmWithTheirBoundsAndFlagsExplained) {
  TempDir tmp;
  WriteFile(tmp.path() / "summary.json", R"json({
  "scenario": "cle", "kind": "closed_loop_estimators", "seed": 15, "metrics": {},
  "estimators": {"fk": {"metrics": {
    "before": {"pos_err_mean_m": 0.00393354, "lateral_err_mean_m": 0.00204321,
               "nees_mean": 0.109, "nees_bound_low": 4.82, "nees_bound_high": 7.30,
               "nees_consistent": false, "mismatch_flagged": false, "mismatch_first_step": -1},
    "after": {"pos_err_mean_m": 7.46356e-05, "lateral_err_mean_m": 6.344e-05,
              "nees_mean": 6.77, "nees_bound_low": 4.47, "nees_bound_high": 8.36,
              "nees_consistent": true, "mismatch_flagged": true, "mismatch_first_step": 9}}}},
  "gates": []})json");
  const std::string html = RenderReport(tmp.path());
  EXPECT_NE(html.find("<tr><td><b>fk</b></td><td class=\"num\">3.93 mm</td><td class=\"num\">"
                      "0.0746 mm</td><td class=\"num\">0.019</td>"),
            std::string::npos)
      << html;
  EXPECT_NE(html.find("0.109 [4.82, 7.3] below"), std::string::npos);
  EXPECT_NE(html.find("6.77 [4.47, 8.36] inside"), std::string::npos);
  EXPECT_NE(html.find("<td>no / yes (step 9)</td>"), std::string::npos);
  EXPECT_NE(html.find("the gates decide pass or fail"), std::string::npos);
  // The flat table is still there, folded below.
  EXPECT_LT(html.find("Before and after, per estimator"), html.find("<details>"));
  EXPECT_NE(html.find("<tr><td>before.pos_err_mean_m</td>"), std::string::npos);
}

TEST(Report, SweepListsMetricsConstantOverEveryRunOnce) {
  TempDir tmp;
  const auto stat = [](double lo, double hi) {
    return "{\"n\": 3, \"mean\": " + std::to_string((lo + hi) / 2) + ", \"std\": 0.1, " +
           "\"median\": 1, \"min\": " + std::to_string(lo) + ", \"max\": " + std::to_string(hi) +
           ", \"ci_low\": 0, \"ci_high\": 2}";
  };
  const auto point = [&](const std::string& name, double err_lo, double k) {
    return "{\"point\": \"" + name + "\", \"runs\": 3, \"succeeded\": 3, \"metrics\": {" +
           "\"nees_dof\": " + stat(6, 6) + ", \"err_m\": " + stat(err_lo, 0.9) +
           ", \"per_point_k\": " + stat(k, k) + "}}";
  };
  WriteFile(tmp.path() / "aggregate.json",
            "{\"sweep\": \"s\", \"seeds\": [1, 2, 3], "
            "\"points\": [" +
                point("a", 0.1, 1) + ", " + point("b", 0.2, 2) + "]}");
  const std::string html = RenderReport(tmp.path());
  EXPECT_EQ(Count(html, "<td>nees_dof</td>"), 1) << html;
  EXPECT_NE(html.find("<tr><td>nees_dof</td><td class=\"num\">6</td></tr>"), std::string::npos);
  EXPECT_LT(html.find("<h3>Point b</h3>"), html.find("<td>nees_dof</td>"));
  // Varying over seeds, or constant within a point but not across points: per point.
  EXPECT_EQ(Count(html, "<td>err_m</td>"), 2);
  EXPECT_EQ(Count(html, "<td>per_point_k</td>"), 2);
}

TEST(Report, QuotingHelpers) {
  EXPECT_EQ(HtmlEscape("a<b>&\"'"), "a&lt;b&gt;&amp;&quot;&#39;");
  EXPECT_EQ(scenarios::ShellQuote("plain/path-1.yaml"), "plain/path-1.yaml");
  EXPECT_EQ(scenarios::ShellQuote("a b"), "'a b'");
  EXPECT_EQ(scenarios::ShellQuote("it's"), "'it'\\''s'");
  EXPECT_EQ(scenarios::ShellQuote(""), "''");
  EXPECT_EQ(scenarios::CommandLine({"flexbench", "run", "x y.yaml", "--set", "a.b=[1, 2]"}),
            "flexbench run 'x y.yaml' --set 'a.b=[1, 2]'");
  EXPECT_EQ(scenarios::UrlPath("frames/a b#?.png"), "frames/a%20b%23%3F.png");
  EXPECT_EQ(scenarios::UrlPath("c:d.png"), "c%3Ad.png");
}

}  // namespace
}  // namespace flexbench::testing
