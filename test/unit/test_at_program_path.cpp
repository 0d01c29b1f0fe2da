// planProgram: a G-code program as the '@' controller's operations (M1@ ... #@), split where the
// program's own steps and its spindle, coolant and tool changes require.
#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <vector>

#include "cnc_bridge/at_protocol/program_path.h"
#include "cnc_bridge/common/error.h"

namespace ap = cnc_bridge::at_protocol;
using Kind = cnc_bridge::gcode::ProgramStep::Kind;

namespace
{
std::vector<ap::OperationPlan> plan(const std::string& program, bool program_commands = true)
{
  std::istringstream in(program);
  ap::ProgramPlanOptions options;
  options.fallback_feed = 10.0;
  options.program_commands = program_commands;
  options.program_commands_setting = "/mill/program_commands";
  return ap::planProgram(in, cnc_bridge::gcode::ParserOptions(), options, {1000, 2000, 3000});
}

std::string refusal(const std::string& program, bool program_commands)
{
  try
  {
    plan(program, program_commands);
  }
  catch (const cnc_bridge::ConfigError& e)
  {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(ProgramPath, AProgramWithoutStepsIsOneOperationFromTheStart)
{
  const auto plans = plan("G21 G90\nG0 X5 Y5\nG1 X10 F600\nG1 Y10\n");
  ASSERT_EQ(plans.size(), 1u);
  EXPECT_EQ(plans[0].points.front(), (ap::Vec3{1000, 2000, 3000}));
  // Program coordinates: the program's Z is 0 until it says otherwise, wherever the machine starts.
  EXPECT_EQ(plans[0].points.back(), (ap::Vec3{10000, 10000, 0}));
  ASSERT_EQ(plans[0].feeds.size(), 3u);
  EXPECT_GT(plans[0].feeds[0], 1e6);          // rapid: as fast as the axes allow
  EXPECT_DOUBLE_EQ(plans[0].feeds[1], 10.0);  // F600 mm/min
  EXPECT_TRUE(plans[0].cuts);
  EXPECT_FALSE(plans[0].after);
}

TEST(ProgramPath, StopsAndDwellsEndAnOperationAndTheNextStartsWhereItEnded)
{
  const auto plans = plan("G21 G90\nG1 X10 F600\nM00\nG1 X20\nM01\nG1 X30\nG04 P0.25\nG1 X40\nM30\nG1 X99\n");
  ASSERT_EQ(plans.size(), 4u);
  const std::vector<Kind> after{Kind::kStop, Kind::kOptionalStop, Kind::kDwell, Kind::kEnd};
  for (size_t k = 0; k < plans.size(); ++k)
  {
    ASSERT_TRUE(plans[k].after) << k;
    EXPECT_EQ(plans[k].after->kind, after[k]) << k;
    if (k > 0)
    {
      EXPECT_EQ(plans[k].points.front(), plans[k - 1].points.back()) << k;
    }
  }
  EXPECT_DOUBLE_EQ(plans[2].after->dwell_s, 0.25);
  EXPECT_EQ(plans[3].points.back()[0], 40000);  // X99 after M30 is never planned
}

TEST(ProgramPath, AMachineCommandAfterACutStartsANewOperationBeforeItAppliesToTheOneUnderWay)
{
  // Positioning rapid, then coolant and spindle: they apply to the first operation (its P@ and
  // S@ come before its setpoints). The spindle change after the cut starts a second operation.
  const auto plans = plan("G21 G90\nG0 X5\nM08\nS6000 M03\nG1 X10 F600\nS3000\nG1 X20\nT4 M06\nG1 X30\nM09\n");
  ASSERT_EQ(plans.size(), 4u);
  EXPECT_TRUE(plans[0].coolant);
  EXPECT_DOUBLE_EQ(plans[0].spindle_rpm, 6000.0);
  EXPECT_EQ(plans[0].points.size(), 3u);  // start, X5, X10
  EXPECT_DOUBLE_EQ(plans[1].spindle_rpm, 3000.0);
  EXPECT_TRUE(plans[1].coolant);
  EXPECT_EQ(plans[1].tool, -1);
  EXPECT_EQ(plans[2].tool, 4);
  EXPECT_EQ(plans[2].points.back()[0], 30000);
  // M09 after the last cut: coolant is switched only at an operation's start, so it is an
  // operation of its own, without moves, at the last point.
  EXPECT_FALSE(plans[3].coolant);
  ASSERT_EQ(plans[3].points.size(), 1u);
  EXPECT_EQ(plans[3].points[0], plans[2].points.back());
}

TEST(ProgramPath, MachineCommandsAreRefusedNamingTheLineAndTheSettingWhenNotTaken)
{
  const std::string text = refusal("G21 G90\nG0 X5\nS6000 M03\nG1 X10 F600\n", false);
  EXPECT_NE(text.find("line 3"), std::string::npos) << text;
  EXPECT_NE(text.find("set /mill/program_commands true"), std::string::npos) << text;
  // A program with only moves and its own stops needs no such setting.
  EXPECT_EQ(refusal("G21 G90\nG1 X10 F600\nM00\nG1 X0\nM30\n", false), "");
}

TEST(ProgramPath, ACounterClockwiseSpindleIsRefused)
{
  const std::string text = refusal("G21 G90\nM04 S1000\nG1 X1 F100\n", true);
  EXPECT_NE(text.find("line 2"), std::string::npos) << text;
  EXPECT_NE(text.find("clockwise only"), std::string::npos) << text;
}

// The whole program is checked while it is planned, before anything is sent: a spindle speed above
// ~spindle_max_rpm in a later operation, a coordinate outside the protocol's range or the soft
// limits, each refused naming its line.
TEST(ProgramPath, TheWholeProgramIsCheckedNamingTheLine)
{
  const auto refusedWith = [](const std::string& program, const cnc_bridge::SoftLimits& limits)
  {
    std::istringstream in(program);
    ap::ProgramPlanOptions options;
    options.fallback_feed = 10.0;
    options.program_commands = true;
    options.spindle_max_rpm = 24000;
    options.soft_limits = limits;
    try
    {
      ap::planProgram(in, cnc_bridge::gcode::ParserOptions(), options, {0, 0, 0});
    }
    catch (const cnc_bridge::Error& e)
    {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  const cnc_bridge::SoftLimits none;
  const std::string spindle = refusedWith("G21 G90\nM03 S1000\nG1 X10 F600\nM03 S30000\nG1 X20\n", none);
  EXPECT_EQ(spindle.rfind("program refused: line 4: ", 0), 0u) << spindle;
  EXPECT_NE(spindle.find("spindle speed above ~spindle_max_rpm (24000"), std::string::npos) << spindle;
  EXPECT_NE(refusedWith("G21 G90\nG1 X10 F600\nG1 X3000000\n", none).find("program refused: line 3: a coordinate"),
            std::string::npos);
  cnc_bridge::SoftLimits limits;
  limits.setting = "/mill/soft_limits";
  limits.axes[2] = std::make_pair(-0.1, 0.0);
  EXPECT_EQ(refusedWith("G21 G90\nG1 X10 F600\nG1 Z-50\nG0 Z5\n", limits),
            "program refused: line 4: Z 0.005 m is outside the soft limits -0.1..0 m (/mill/soft_limits)");
  EXPECT_EQ(refusedWith("G21 G90\nG1 X10 F600\nG1 Z-50\n", limits), "accepted");
}

TEST(ProgramPath, RoundToPulsesMakesWholePulsesAndRefusesPointsOutOfRange)
{
  ap::OperationPlan p;
  p.points = {{0.4, 1.6, -2.5}};
  ap::roundToPulses(p);
  EXPECT_EQ(p.points[0], (ap::Vec3{0, 2, -3}));
  p.points = {{3e9, 0, 0}};
  EXPECT_THROW(ap::roundToPulses(p), cnc_bridge::ConfigError);
}
