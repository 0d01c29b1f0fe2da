// cnc_plan, run as a user runs it: its CSV setpoints must be the ones at_controller_node streams for
// the same program (the node plans through planProgram, roundToPulses, Trajectory and
// TrajectoryStream, which these tests call the same way), for both profiles, operation after
// operation where the program's own steps split it; the PNG is a PNG; the printed worst limit
// ratio of the S-curve is at most 1.
#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <memory>
#include <sstream>

#include "cnc_bridge/at_protocol/planner.h"
#include "cnc_bridge/at_protocol/program_path.h"
#include "temp_dir.h"

namespace ap = cnc_bridge::at_protocol;

namespace
{
const char* kProgram =
    "G21 G90 G17\nG0 X5 Y5 Z2\nG1 Z-1 F300\nG1 X30 F900\nG3 X40 Y15 R10\nG1 Y30\nG2 X30 Y40 I-10 J0\n"
    "G0 Z5\nM3 S1000\nG98 G81 X10 Y10 R1 Z-3 F120\nX20\nG80\nG0 X0 Y0 Z0\nM30\n";

std::string run(const std::string& args, int& status)
{
  std::string out;
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen((std::string(CNC_PLAN) + " " + args + " 2>&1").c_str(), "r"),
                                             pclose);
  char buffer[4096];
  while (fgets(buffer, sizeof buffer, pipe.get()))
  {
    out += buffer;
  }
  status = pclose(pipe.release());
  return out;
}

struct Row
{
  double t_s;
  std::array<int32_t, 3> position;
  std::array<int, 3> feed;
  int operation;
};

std::vector<Row> readCsv(const std::string& path)
{
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);  // header
  std::vector<Row> rows;
  while (std::getline(in, line))
  {
    std::istringstream cells(line);
    std::string cell;
    std::vector<double> v;
    while (std::getline(cells, cell, ','))
    {
      v.push_back(std::stod(cell));
    }
    rows.push_back(
        {v[0], {int32_t(v[1]), int32_t(v[2]), int32_t(v[3])}, {int(v[4]), int(v[5]), int(v[6])}, int(v.back())});
  }
  return rows;
}

// The setpoints of every operation in order, as the node streams them (with ~program_commands).
std::vector<ap::Setpoint> nodeSetpoints(const std::string& program, ap::Profile profile)
{
  ap::PlannerLimits limits;  // the node's defaults: 0.05 m/s, 0.5 m/s^2, 10 m/s^3 ... in mm
  limits.profile = profile;
  ap::ProgramPlanOptions options;
  options.fallback_feed = 10.0;
  options.program_commands = true;
  std::ifstream in(program);
  std::vector<ap::Setpoint> out;
  for (ap::OperationPlan& plan : ap::planProgram(in, cnc_bridge::gcode::ParserOptions(), options, {0, 0, 0}))
  {
    ap::roundToPulses(plan);
    ap::TrajectoryStream stream(ap::Trajectory(plan.points, plan.feeds, limits));
    ap::Setpoint sp;
    while (stream.next(sp))
    {
      out.push_back(sp);
    }
  }
  return out;
}
}  // namespace

TEST(CncPlan, SetpointsAreTheOnesTheNodeStreamsForBothProfiles)
{
  cnc_bridge::test::TempDir dir;
  const std::string program = dir.write("part.nc", kProgram);
  for (const auto& [name, profile] :
       {std::pair{"trapezoid", ap::Profile::kTrapezoid}, std::pair{"scurve", ap::Profile::kSCurve}})
  {
    SCOPED_TRACE(name);
    const std::string csv = dir.file(std::string(name) + ".csv");
    int status = -1;
    const std::string out = run("--gcode " + program + " --profile " + name + " --csv " + csv, status);
    ASSERT_EQ(status, 0) << out;
    const std::vector<Row> rows = readCsv(csv);
    const std::vector<ap::Setpoint> expected = nodeSetpoints(program, profile);
    ASSERT_EQ(rows.size(), expected.size());
    ASSERT_GT(rows.size(), 1000u);
    for (size_t k = 0; k < rows.size(); ++k)
    {
      ASSERT_EQ(rows[k].position, expected[k].position) << "setpoint " << k;
      ASSERT_EQ(rows[k].feed, expected[k].feed) << "setpoint " << k;
    }
    EXPECT_EQ(rows.back().position, (std::array<int32_t, 3>{0, 0, 0}));
    // M3 S1000 after the cuts: the drilling is a second operation (S@ starts it).
    EXPECT_EQ(rows.front().operation, 0);
    EXPECT_EQ(rows.back().operation, 1);
    // The printed total is the setpoints' count in periods.
    std::ostringstream total;
    total << rows.size() << " setpoints, total time";
    EXPECT_NE(out.find(total.str()), std::string::npos) << out;
  }
}

TEST(CncPlan, SCurveReportsItsWorstLimitRatioAndDrawsAPng)
{
  cnc_bridge::test::TempDir dir;
  const std::string program = dir.write("part.nc", kProgram);
  int status = -1;
  const std::string out = run(
      "--gcode " + program + " --profile scurve --csv " + dir.file("s.csv") + " --png " + dir.file("s.png"), status);
  ASSERT_EQ(status, 0) << out;
  const size_t at = out.find("worst limit ratio ");
  ASSERT_NE(at, std::string::npos) << out;
  const double ratio = std::stod(out.substr(at + 18));
  EXPECT_LE(ratio, 1.0 + 1e-6);
  EXPECT_GT(ratio, 0.3);
  std::ifstream png(dir.file("s.png"), std::ios::binary);
  char magic[8] = {};
  png.read(magic, 8);
  EXPECT_EQ(std::string(magic + 1, 3), "PNG");
}

TEST(CncPlan, BadInputSaysWhatToCheckAndWritesNothing)
{
  cnc_bridge::test::TempDir dir;
  const std::string program = dir.write("bad.nc", "G1 X10 F100\nG1 X1 X2\n");
  int status = -1;
  std::string out = run("--gcode " + program + " --csv " + dir.file("bad.csv"), status);
  EXPECT_NE(status, 0);
  EXPECT_NE(out.find("line 2, column 7"), std::string::npos) << out;
  EXPECT_FALSE(std::ifstream(dir.file("bad.csv")).good());
  out = run("--points " + program + " --profile jerky", status);
  EXPECT_NE(status, 0);
  EXPECT_NE(out.find("trapezoid or scurve"), std::string::npos) << out;
}

// A program with its own stops is planned as the node carries it out: one operation per stretch
// between M00, M01 and G04, nothing after M30; the CSV's time runs on through the dwell and the
// printed lines name each step.
TEST(CncPlan, ProgramStopsSplitThePlanAsTheNodeDoes)
{
  cnc_bridge::test::TempDir dir;
  const std::string program = dir.write("stops.nc",
                                        "G21 G90\nG0 X5 Y5 Z2\nG1 X10 F1200\nM00\nG1 X15\nM01\nG1 X20\nG04 P0.3\n"
                                        "G1 X25\nM30\nG1 X99\n");
  int status = -1;
  const std::string out = run("--gcode " + program + " --csv " + dir.file("stops.csv"), status);
  ASSERT_EQ(status, 0) << out;
  const std::vector<Row> rows = readCsv(dir.file("stops.csv"));
  const std::vector<ap::Setpoint> expected = nodeSetpoints(program, ap::Profile::kTrapezoid);
  ASSERT_EQ(rows.size(), expected.size());
  for (size_t k = 0; k < rows.size(); ++k)
  {
    ASSERT_EQ(rows[k].position, expected[k].position) << "setpoint " << k;
  }
  EXPECT_EQ(rows.back().operation, 3);
  EXPECT_EQ(rows.back().position, (std::array<int32_t, 3>{25000, 5000, 2000}));  // X99 after M30: never
  EXPECT_NE(out.find("operation 1: 2 segments, then M00 program stop at line 4"), std::string::npos) << out;
  EXPECT_NE(out.find("then M01 optional stop at line 6"), std::string::npos) << out;
  EXPECT_NE(out.find("then G04 dwell of 0.300 s at line 8"), std::string::npos) << out;
  EXPECT_NE(out.find("4 operations"), std::string::npos) << out;
  // Time steps by the period within an operation, and by the dwell as well across the G04.
  for (size_t k = 1; k < rows.size(); ++k)
  {
    const double step = rows[k].t_s - rows[k - 1].t_s;
    const bool across_dwell = rows[k - 1].operation == 2 && rows[k].operation == 3;
    EXPECT_NEAR(step, across_dwell ? 0.301 : 0.001, 1e-6) << "setpoint " << k;
  }
}

TEST(CncPlan, ProgramCommandsRefusedWhenSwitchedOffNamingTheLineAndTheOption)
{
  cnc_bridge::test::TempDir dir;
  const std::string program = dir.write("spindle.nc", "G21 G90\nG0 X5\nS8000 M03\nG1 X10 F600\n");
  int status = -1;
  const std::string out = run("--gcode " + program + " --program-commands false --csv " + dir.file("s.csv"), status);
  EXPECT_NE(status, 0);
  EXPECT_NE(out.find("line 3"), std::string::npos) << out;
  EXPECT_NE(out.find("--program-commands"), std::string::npos) << out;
  EXPECT_FALSE(std::ifstream(dir.file("s.csv")).good());
}
