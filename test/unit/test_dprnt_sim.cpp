// The macro interpreter behind `sim_haas_serial dprnt`: the rostests trust it to print what a Haas
// control would, so its loops, moves, probe cycle and DPRNT output are checked here on their own.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>

#include "../../src/sim/haas_serial/dprnt_program.h"
#include "cnc_bridge/common/error.h"
#include "temp_dir.h"

using cnc_bridge::ConfigError;
using cnc_bridge::sim::MacroMachine;
using cnc_bridge::sim::MacroProgram;

namespace
{
std::vector<std::string> run(const std::string& text, MacroMachine& machine)
{
  std::vector<std::string> lines;
  MacroProgram::parse(text).run(machine,
                                [&](const std::string& line)
                                {
                                  lines.push_back(line);
                                  return true;
                                });
  return lines;
}

std::vector<std::string> run(const std::string& text)
{
  MacroMachine machine;
  machine.max_blocks = 10000;
  return run(text, machine);
}
}  // namespace

TEST(DprntSim, ManualExampleProgram)
{
  // N1 #1= 1.5436 ; N2 DPRNT[X#1[44]*Z#1[03]*T#1[40]] ; N4 DPRNT[] ;
  EXPECT_EQ(run("%\nO0001\nN1 #1= 1.5436 ;\nN2 DPRNT[X#1[44]*Z#1[03]*T#1[40]] ;\nN4 DPRNT[] ;\n%\n"),
            (std::vector<std::string>{"X   1.5436 Z1.544 T   1", ""}));
}

TEST(DprntSim, ExpressionsAndComments)
{
  MacroMachine machine;
  run("#1 = [2 + 3] * 4 - 6 / 3 (EIGHTEEN)\n#2 = ABS[-2.5] + SQRT[16] + ROUND[1.5] + FIX[1.9] + FUP[1.1]\n"
      "#3 = #[1 + 1] ; #4 = SIN[90] + COS[0]\n#5 = [1 LT 2] AND [3 GE 3] ; #6 = [1 EQ 2] OR [2 NE 2]",
      machine);
  EXPECT_DOUBLE_EQ(machine.variables[1], 18.0);
  EXPECT_DOUBLE_EQ(machine.variables[2], 2.5 + 4 + 2 + 1 + 2);
  EXPECT_DOUBLE_EQ(machine.variables[3], machine.variables[2]);
  EXPECT_NEAR(machine.variables[4], 2.0, 1e-12);
  EXPECT_EQ(machine.variables[5], 1.0);
  EXPECT_EQ(machine.variables[6], 0.0);
}

TEST(DprntSim, OpenDncGridProbingOverAPlane)
{
  // OpenDNC's cycle: G65 P9995 ...; DPRNT[#5223[44]]; G00 G91 X.5; three points in a row.
  MacroMachine machine;
  machine.surface = [](double x, double y) { return -0.01 + 0.002 * x + 0.001 * y; };
  const auto lines =
      run("G90 G00 X0 Y1.\n#1 = 0\nWHILE [#1 LT 3] DO1\nG65 P9995 W54. A20. H-1.\nDPRNT[#5223[44]]\nG00 G91 X.5\nG90\n"
          "#1 = #1 + 1\nEND1\nM30\nDPRNT[NEVER]",
          machine);
  // z = -0.01 + 0.002 x + 0.001 at x = 0, 0.5, 1.0: -0.009, -0.008, -0.007.
  EXPECT_EQ(lines, (std::vector<std::string>{"  -0.0090", "  -0.0080", "  -0.0070"}));
  EXPECT_DOUBLE_EQ(machine.position[0], 1.5);
  EXPECT_DOUBLE_EQ(machine.variables[5061], 1.0);  // trigger position of the last probe
  EXPECT_DOUBLE_EQ(machine.variables[5062], 1.0);
}

TEST(DprntSim, MachinePositionIsWorkPositionPlusTheG54Offset)
{
  MacroMachine machine;
  machine.variables[5221] = -12.5;  // G54 X, Y
  machine.variables[5222] = -8.25;
  machine.surface = [](double, double) { return 0.0035; };
  const auto lines =
      run("G90 G00 X1. Y2.\nG65 P9995 W54. A20. H-1.\nG00 G91 X.5\n"
          "DPRNT[MACHINE*X#5021[44]*Y#5022[44]*Z#5023[44]]\nDPRNT[WORK*X#5041[44]*Y#5042[44]]",
          machine);
  // Machine X = 1.5 - 12.5, Y = 2 - 8.25, Z = 0 + the probed G54 Z offset.
  EXPECT_EQ(lines,
            (std::vector<std::string>{"MACHINE X -11.0000 Y  -6.2500 Z   0.0035", "WORK X   1.5000 Y   2.0000"}));
}

TEST(DprntSim, NestedLoopsAndGoto)
{
  const auto lines =
      run("#1 = 0\nWHILE [#1 LT 2] DO1\n#2 = 0\nWHILE [#2 LT 2] DO2\nDPRNT[R#1[10]*C#2[10]]\n#2 = #2 + 1\nEND2\n"
          "#1 = #1 + 1\nEND1\nIF [#1 EQ 2] GOTO10\nDPRNT[SKIPPED]\nN10 DPRNT[DONE]");
  EXPECT_EQ(lines, (std::vector<std::string>{"R0 C0", "R0 C1", "R1 C0", "R1 C1", "DONE"}));
}

TEST(DprntSim, ErrorsNameTheLine)
{
  const auto message = [](const std::string& text)
  {
    try
    {
      run(text);
    }
    catch (const ConfigError& e)
    {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message("#1 = 5\nWHILE [#1 LT 2] DO1\n").find("line 2"), std::string::npos);
  EXPECT_NE(message("DPRNT[X#1[4]]").find("line 1"), std::string::npos);
  EXPECT_NE(message("#1 = 1 / 0").find("division"), std::string::npos);
  EXPECT_NE(message("IF [1 EQ 1] GOTO99").find("N99"), std::string::npos);
  EXPECT_NE(message("WHILE [1 EQ 1] DO1\nEND1").find("endless"), std::string::npos);
}

namespace
{
std::string errorOf(const std::string& text, MacroMachine& machine)
{
  try
  {
    run(text, machine);
  }
  catch (const ConfigError& e)
  {
    return e.what();
  }
  return "no error";
}
}  // namespace

// G65 P9811 X/Y: the probe moves from where it is toward the target and stops on the part's side;
// a part square to the axes, its corner at (-0.25, -0.25).
TEST(DprntSim, SingleSurfaceXyProbeTouchesThePartsSides)
{
  MacroMachine machine;
  machine.side_contact = cnc_bridge::sim::rectangularPartSides(-0.25, -0.25, 0.0);
  const auto lines =
      run("G90 G00 X.5 Y-.75 Z.1\nG65 P9811 Y0.\nDPRNT[EDGEX*X#5061[44]*Y#5062[44]*Z#5063[44]]\n"
          "G00 X-.75 Y2.\nG65 P9811 X0.\nDPRNT[EDGEY*X#5061[44]*Y#5062[44]]\n"
          "G91 G65 P9811 X1.\nDPRNT[EDGEY*X#5061[44]]",
          machine);
  EXPECT_EQ(lines, (std::vector<std::string>{"EDGEX X   0.5000 Y  -0.2500 Z   0.1000", "EDGEY X  -0.2500 Y   2.0000",
                                             "EDGEY X  -0.2500"}));
  // The probe returns to where it started.
  EXPECT_DOUBLE_EQ(machine.position[0], -0.75);
  EXPECT_DOUBLE_EQ(machine.position[1], 2.0);
}

// A part turned 10 degrees: the front face rises toward +X, the left face leans toward -X.
TEST(DprntSim, SingleSurfaceXyProbeFollowsATurnedPart)
{
  const double yaw = 10.0 * M_PI / 180.0;
  MacroMachine machine;
  machine.side_contact = cnc_bridge::sim::rectangularPartSides(-0.25, -0.25, yaw);
  run("G90 G00 X.5 Y-.75\nG65 P9811 Y0.\n#1 = #5061\n#2 = #5062\nG00 X-.75 Y2.\nG65 P9811 X0.", machine);
  EXPECT_DOUBLE_EQ(machine.variables[1], 0.5);
  EXPECT_NEAR(machine.variables[2], -0.25 + 0.75 * std::tan(yaw), 1e-12);
  EXPECT_NEAR(machine.variables[5061], -0.25 - 2.25 * std::tan(yaw), 1e-12);
  EXPECT_DOUBLE_EQ(machine.variables[5062], 2.0);
}

// What a control alarms on stops the run with the line: no side modelled, a probe that touches
// nothing (beyond the corner, or already on the part moving away), X and Y in one cycle.
TEST(DprntSim, SingleSurfaceXyProbeErrorsNameTheCause)
{
  MacroMachine no_sides;
  EXPECT_NE(errorOf("G65 P9811 X1.", no_sides).find("--part-corner"), std::string::npos);
  MacroMachine machine;
  machine.side_contact = cnc_bridge::sim::rectangularPartSides(-0.25, -0.25, 0.0);
  const std::string beyond_the_corner = errorOf("G00 X-.5 Y-.75\nG65 P9811 Y0.", machine);
  EXPECT_NE(beyond_the_corner.find("line 2"), std::string::npos) << beyond_the_corner;
  EXPECT_NE(beyond_the_corner.find("without touching the part"), std::string::npos) << beyond_the_corner;
  EXPECT_NE(errorOf("G00 X1. Y1.\nG65 P9811 Y2.", machine).find("without touching"), std::string::npos);
  EXPECT_NE(errorOf("G65 P9811 X1. Y1.", machine).find("X or Y"), std::string::npos);
  EXPECT_NE(errorOf("G65 P9811 Z1.", machine).find("X or Y"), std::string::npos);
}

// `--part-corner` is three finite numbers; anything else stops the simulator before it opens its
// port (exit 2), naming the value at fault, so a rostest with a typo fails at once, not on a probe.
TEST(DprntSim, APartCornerThatIsNotThreeFiniteNumbersIsRefusedNamingIt)
{
  const cnc_bridge::test::TempDir dir("test_dprnt_sim");
  const std::string program = dir.write("O1.nc", "%\nO00001\nG65 P9811 X1.\nM30\n%\n");
  const std::string link = dir.file("port");
  const auto run = [&](const std::string& corner)
  {
    const std::string command = std::string(SIM_HAAS_SERIAL) + " dprnt --link " + link + " --program " + program +
                                " --part-corner '" + corner + "' 2>&1";
    FILE* out = ::popen(command.c_str(), "r");
    std::string said;
    char buffer[256];
    while (out != nullptr && std::fgets(buffer, sizeof(buffer), out) != nullptr)
      said += buffer;
    const int status = out != nullptr ? ::pclose(out) : -1;
    return std::make_pair(WIFEXITED(status) ? WEXITSTATUS(status) : -1, said);
  };
  for (const auto& [corner, named] :
       std::vector<std::pair<std::string, std::string>>{{"1,x,2", "'x' is not a finite number"},
                                                        {"1,nan,2", "'nan' is not a finite number"},
                                                        {"1e400,0,0", "'1e400' is not a finite number"},
                                                        {"1,2", "expected X,Y,YAW (three numbers)"},
                                                        {"1,2,3,4", "expected X,Y,YAW (three numbers)"},
                                                        {"0.5 ,1,2", "'0.5 ' is not a finite number"}})
  {
    SCOPED_TRACE(corner);
    const auto [status, said] = run(corner);
    EXPECT_EQ(status, 2) << said;
    EXPECT_NE(said.find("--part-corner " + corner + ": " + named), std::string::npos) << said;
    EXPECT_FALSE(cnc_bridge::test::exists(link)) << "the simulator opened its port";
  }
}
