// Inputs that pass the top-level checks but hang or exhaust memory further in: files an MJCF
// names (includes, meshes, textures) that are pipes or devices, YAML and CSV files under their
// byte caps that would take gigabytes, result files given to `report` that are too big, too
// deep or of the wrong shape, and absurd finite values. Each must end within seconds with
// exit 2 and one line naming the file.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "tests/common/test_util.h"

namespace flexbench::testing {
namespace {

namespace fs = std::filesystem;

// Every command has a deadline: a hang is a failure, not a stuck test. The address space is
// capped so that a reader building gigabytes fails here as it would on a small machine.
CommandResult Fb(const std::string& args, const std::string& stdin_from = "/dev/null") {
  return RunCommand("ulimit -v 3000000; timeout 30 " + Flexbench() + " " + args + " <" +
                    stdin_from);
}

// A one-line error: exit 2 and the last stderr line holds `needle`.
void ExpectBadInput(const CommandResult& r, const std::string& needle) {
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find(needle), std::string::npos) << r.err;
}

// planar3 with `extra` inside <mujoco> (before its first element).
std::string ModelWith(const std::string& extra) {
  std::string xml = ReadFile(fs::path(SourceDir()) / "models" / "planar3.xml");
  const size_t open = xml.find("<mujoco");
  const size_t end = xml.find('>', open);
  return xml.insert(end + 1, "\n" + extra + "\n");
}

std::string SmokeYaml(const fs::path& model) {
  return "scenario: smoke_copy\nkind: smoke\nseed: 3\nmodel: " + model.string() +
         "\ncamera: overview\nconfiguration: {joint1: 0.35, joint2: -0.6, joint3: 0.5}\n";
}

class InputFiles : public ::testing::Test {
 protected:
  fs::path Path(const std::string& name) const { return tmp_.path() / name; }
  // `run` and `inspect` on a model holding `extra`; both must refuse it naming `needle`.
  void ExpectModelRefused(const std::string& extra, const std::string& needle) {
    WriteFile(Path("model.xml"), ModelWith(extra));
    WriteFile(Path("smoke.yaml"), SmokeYaml(Path("model.xml")));
    ExpectBadInput(Fb("run " + Path("smoke.yaml").string() + " --out " + Path("out").string()),
                   needle);
    EXPECT_FALSE(fs::exists(Path("out")));
    ExpectBadInput(Fb("inspect " + Path("model.xml").string()), needle);
  }
  TempDir tmp_;
};

TEST_F(InputFiles, IncludeOfAFifoIsRefusedNotWaitedOn) {
  ASSERT_EQ(mkfifo(Path("part.xml").c_str(), 0600), 0);
  ExpectModelRefused("<include file=\"part.xml\"/>",
                     "include 'part.xml': " + Path("part.xml").string() + ": not a regular file");
}

TEST_F(InputFiles, IncludeOfALinkToStdinIsRefused) {
  fs::create_symlink("/dev/stdin", Path("stdin.xml"));
  ExpectModelRefused("<include file=\"stdin.xml\"/>", "stdin.xml: not a regular file");
}

TEST_F(InputFiles, NestedIncludeOfAFifoIsRefused) {
  ASSERT_EQ(mkfifo(Path("inner.xml").c_str(), 0600), 0);
  WriteFile(Path("outer.xml"), "<mujoco>\n  <include file=\"inner.xml\"/>\n</mujoco>\n");
  ExpectModelRefused("<include file=\"outer.xml\"/>",
                     "outer.xml:2: include 'inner.xml': " + Path("inner.xml").string());
}

TEST_F(InputFiles, MeshThatIsDevZeroIsRefused) {
  fs::create_symlink("/dev/zero", Path("zero.obj"));
  ExpectModelRefused(
      "<asset><mesh name=\"z\" file=\"zero.obj\"/></asset>",
      "<mesh> file 'zero.obj': " + Path("zero.obj").string() + ": not a regular file");
}

TEST_F(InputFiles, StlMeshThatIsAFifoIsRefused) {
  ASSERT_EQ(mkfifo(Path("part.stl").c_str(), 0600), 0);
  ExpectModelRefused("<asset><mesh name=\"s\" file=\"part.stl\"/></asset>",
                     "part.stl: not a regular file");
}

TEST_F(InputFiles, TextureAndHfieldFilesAreChecked) {
  ASSERT_EQ(mkfifo(Path("tex.png").c_str(), 0600), 0);
  ExpectModelRefused("<asset><texture name=\"t\" type=\"2d\" file=\"tex.png\"/></asset>",
                     "<texture> file 'tex.png': " + Path("tex.png").string());
  fs::create_symlink("/dev/zero", Path("h.png"));
  ExpectModelRefused("<asset><hfield name=\"h\" file=\"h.png\" size=\"1 1 1 1\"/></asset>",
                     "<hfield> file 'h.png'");
}

TEST_F(InputFiles, MeshInMeshdirIsChecked) {
  fs::create_directories(Path("meshes"));
  fs::create_symlink("/dev/zero", Path("meshes/zero.obj"));
  ExpectModelRefused(
      "<compiler meshdir=\"meshes\"/><asset><mesh name=\"z\" file=\"zero.obj\"/></asset>",
      Path("meshes/zero.obj").string() + ": not a regular file");
}

TEST_F(InputFiles, AbsurdPositionInTheModelIsRefused) {
  std::string xml = ReadFile(fs::path(SourceDir()) / "models" / "planar3.xml");
  const std::string base = "<body name=\"base\" pos=\"0 0 0.05\">";
  const size_t at = xml.find(base);
  ASSERT_NE(at, std::string::npos);
  xml.replace(at, base.size(), "<body name=\"base\" pos=\"-1e308 0 0.05\">");
  WriteFile(Path("bad.xml"), xml);
  WriteFile(Path("smoke.yaml"), SmokeYaml(Path("bad.xml")));
  const CommandResult r =
      Fb("run " + Path("smoke.yaml").string() + " --out " + Path("out").string());
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(LastLine(r.err).find("bad.xml:"), std::string::npos) << r.err;
  EXPECT_NE(LastLine(r.err).find("'-1e308' is out of range (|value| <= 1e6 m)"), std::string::npos)
      << r.err;
}

TEST_F(InputFiles, AbsurdJointValueFromSetIsRefused) {
  WriteFile(Path("smoke.yaml"), SmokeYaml(fs::path(SourceDir()) / "models" / "planar3.xml"));
  const CommandResult r = Fb("run " + Path("smoke.yaml").string() + " --out " +
                             Path("out").string() + " --set configuration.joint1=1e300");
  ExpectBadInput(r, "--set configuration.joint1");
  EXPECT_NE(LastLine(r.err).find("out of range"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(Path("out")));
}

// A URDF goes through the same checks (MuJoCo's importer opens its meshes); lines are the
// URDF's own.
TEST_F(InputFiles, UrdfMeshDeviceAndAbsurdOriginAreRefused) {
  fs::create_symlink("/dev/zero", Path("zero.obj"));
  const std::string joint =
      "  <joint name=\"j1\" type=\"revolute\"><parent link=\"base\"/><child link=\"l1\"/>"
      "<axis xyz=\"0 0 1\"/><limit lower=\"-1\" upper=\"1\" effort=\"1\" velocity=\"1\"/>";
  WriteFile(Path("mesh.urdf"),
            "<robot name=\"r\">\n  <link name=\"base\"><visual><geometry><mesh "
            "filename=\"zero.obj\"/></geometry></visual></link>\n  <link name=\"l1\"/>\n" +
                joint + "</joint>\n</robot>\n");
  ExpectBadInput(Fb("inspect " + Path("mesh.urdf").string()), "zero.obj: not a regular file");
  WriteFile(Path("far.urdf"),
            "<robot name=\"r\">\n  <link name=\"base\"/>\n  <link "
            "name=\"l1\"/>\n" +
                joint + "<origin xyz=\"1e300 0 0\"/></joint>\n</robot>\n");
  ExpectBadInput(Fb("inspect " + Path("far.urdf").string()),
                 "far.urdf:4: <origin> xyz: '1e300' is out of range");
}

// identify loads the declared file's model through the same scan.
TEST_F(InputFiles, IdentifyRefusesAModelIncludingAFifo) {
  ASSERT_EQ(mkfifo(Path("part.xml").c_str(), 0600), 0);
  WriteFile(Path("model.xml"), ModelWith("<include file=\"part.xml\"/>"));
  std::string declared = ReadFile(fs::path(SourceDir()) / "models" / "planar3.declared.yaml");
  const size_t at = declared.find("\nmodel:");
  ASSERT_NE(at, std::string::npos);
  declared.replace(at, declared.find('\n', at + 1) - at, "\nmodel: " + Path("model.xml").string());
  WriteFile(Path("declared.yaml"), declared);
  WriteFile(Path("cal.csv"), "joint1,joint2,joint3,x,y,z\n0.1,0.2,0.3,0.4,0.1,0.1\n");
  WriteFile(Path("val.csv"), "joint1,joint2,joint3,x,y,z\n0.2,0.2,0.3,0.4,0.1,0.1\n");
  ExpectBadInput(Fb("identify --declared " + Path("declared.yaml").string() + " --calibration " +
                    Path("cal.csv").string() + " --validation " + Path("val.csv").string() +
                    " --out " + Path("out").string()),
                 "include 'part.xml': " + Path("part.xml").string() + ": not a regular file");
  EXPECT_FALSE(fs::exists(Path("out")));
}

// A value no check bounds that makes a metric NaN ends the run as bad input, not a null.
TEST_F(InputFiles, NonFiniteMetricIsAnErrorNotANull) {
  const CommandResult r =
      Fb("run " + SourceDir() + "/scenarios/planar3_covariance.yaml --out " + Path("out").string() +
         " --set 'cases.a.q_deg=[1e300, 40, 30]' --set samples=200 --set covariance_samples=1000");
  ExpectBadInput(r, "metric 'a.");
  EXPECT_NE(LastLine(r.err).find("not finite; check the inputs"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(Path("out")));
}

// A list of 3.9 million items in 15 MiB: under the byte cap, gigabytes as a tree.
TEST_F(InputFiles, HugeYamlListIsRefusedWhileParsing) {
  {
    std::ofstream f(Path("big.yaml"));
    f << SmokeYaml(fs::path(SourceDir()) / "models" / "planar3.xml") << "padding:\n";
    const std::string item = "- 1\n";
    for (int i = 0; i < 3900000; ++i) f << item;
  }
  ASSERT_LT(fs::file_size(Path("big.yaml")), 16u << 20);
  const CommandResult r = Fb("run " + Path("big.yaml").string() + " --out " + Path("out").string());
  ExpectBadInput(r, Path("big.yaml").string() + ":");
  EXPECT_NE(LastLine(r.err).find("more than 1000000 YAML nodes"), std::string::npos) << r.err;
}

TEST_F(InputFiles, DeeplyNestedYamlIsRefused) {
  WriteFile(Path("deep.yaml"), SmokeYaml(fs::path(SourceDir()) / "models" / "planar3.xml") +
                                   "deep: " + std::string(5000, '[') + std::string(5000, ']') +
                                   "\n");
  const CommandResult r =
      Fb("run " + Path("deep.yaml").string() + " --out " + Path("out").string());
  ExpectBadInput(r, "deep.yaml:");
  EXPECT_NE(LastLine(r.err).find("nested more than 64 deep"), std::string::npos) << r.err;
}

// 1.5 million calibration rows under the 512 MiB cap: refused with the memory they would take
// (a million are identified within the 2 GB).
TEST_F(InputFiles, CalibrationCsvTooManyRowsForMemoryIsRefused) {
  for (const char* name : {"cal.csv", "val.csv"}) {
    std::ofstream f(Path(name));
    f << "joint1,joint2,joint3,x,y,z\n";
    char row[128];
    for (int i = 0; i < 1500000; ++i) {
      std::snprintf(row, sizeof(row), "%.4f,%.4f,0.1,0.3,%.4f,0.1\n", 1e-6 * i, -1e-6 * i,
                    name[0] == 'c' ? 1e-7 * i : 2e-7 * i);
      f << row;
    }
  }
  const CommandResult r =
      Fb("identify --declared " + SourceDir() + "/models/planar3.declared.yaml --calibration " +
         Path("cal.csv").string() + " --validation " + Path("val.csv").string() + " --out " +
         Path("out").string());
  ExpectBadInput(r, "cal.csv: 1500001 rows need about ");
  EXPECT_NE(LastLine(r.err).find("the limit is"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(Path("out")));
}

class ReportInputs : public ::testing::Test {
 protected:
  // `report` on a folder whose summary.json is `json`.
  CommandResult Report(const std::string& json, const char* file = "summary.json") {
    fs::create_directories(tmp_.path() / "r");
    WriteFile(tmp_.path() / "r" / file, json);
    return Fb("report " + (tmp_.path() / "r").string());
  }
  std::string Summary() const { return (tmp_.path() / "r" / "summary.json").string(); }
  TempDir tmp_;
};

TEST_F(ReportInputs, WrongShapeIsBadInputNamingTheFileAndKey) {
  ExpectBadInput(Report("[]"), Summary() + ": expected a JSON object at the top level");
  ExpectBadInput(Report("{\"scenario\": 5}"), Summary() + ": key 'scenario': expected a string");
  ExpectBadInput(Report("{\"gates\": [1]}"), Summary() + ": key 'gates[0]': expected an object");
  ExpectBadInput(Report("{\"gates\": [{\"passed\": \"yes\"}]}"),
                 Summary() + ": key 'gates[0].passed': expected true or false");
  ExpectBadInput(Report("{\"gates\": {}}"), Summary() + ": key 'gates': expected a list");
  EXPECT_EQ(Report("{\"metrics\": {\"a\": 1}}").exit_code, 0);
}

TEST_F(ReportInputs, SweepAggregateOfTheWrongShapeIsBadInput) {
  const std::string aggregate = (tmp_.path() / "r" / "aggregate.json").string();
  ExpectBadInput(Report("{\"points\": [1]}", "aggregate.json"),
                 aggregate + ": key 'points[0]': expected an object");
  ExpectBadInput(Report("{\"points\": [{\"metrics\": {\"m\": 3}}]}", "aggregate.json"),
                 aggregate + ": key 'points[0].metrics.m': expected an object");
  ExpectBadInput(Report("{\"failed\": [\"x\"]}", "aggregate.json"),
                 aggregate + ": key 'failed[0]': expected an object");
}

TEST_F(ReportInputs, DeepNestingIsRefusedWhileParsing) {
  std::string deep = "{\"metrics\": ";
  for (int i = 0; i < 200000; ++i) deep += "{\"a\": ";
  deep += "1";
  deep += std::string(200000, '}');
  deep += "}";
  ExpectBadInput(Report(deep), Summary() + ": nested more than 64 levels deep");
}

TEST_F(ReportInputs, OversizedSummaryIsRefusedBeforeReading) {
  fs::create_directories(tmp_.path() / "r");
  {
    std::ofstream f(Summary());
    f << "{\"scenario\": \"";
    const std::string chunk(1 << 20, 'x');
    for (int i = 0; i < 65; ++i) f << chunk;
    f << "\"}";
  }
  const CommandResult r = Fb("report " + (tmp_.path() / "r").string());
  ExpectBadInput(r, Summary() + ": ");
  EXPECT_NE(LastLine(r.err).find("more than the 67108864"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(tmp_.path() / "r" / "report.html"));
}

}  // namespace
}  // namespace flexbench::testing
