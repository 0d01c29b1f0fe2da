// ProgramSteps: a program's commands in the order a control carries them out within a block
// (tool change, spindle, coolant, dwell, the moves, then a stop or the end), nothing after M02/M30.
#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <vector>

#include "cnc_bridge/gcode/program_steps.h"

namespace gc = cnc_bridge::gcode;
using Kind = gc::ProgramStep::Kind;

namespace
{
std::vector<gc::ProgramStep> stepsOf(const std::string& program, gc::ParserOptions options = {})
{
  std::istringstream in(program);
  gc::ProgramSteps steps(in, options);
  std::vector<gc::ProgramStep> out;
  gc::ProgramStep step;
  while (steps.next(step))
  {
    out.push_back(step);
  }
  return out;
}

std::vector<Kind> kindsOf(const std::vector<gc::ProgramStep>& steps)
{
  std::vector<Kind> out;
  for (const auto& step : steps)
  {
    out.push_back(step.kind);
  }
  return out;
}
}  // namespace

TEST(ProgramSteps, OneBlockIsCarriedOutInTheControlsOrder)
{
  // Written in the "wrong" order on purpose: the stop is last whatever its place in the block.
  const auto steps = stepsOf("G21 G90\nM00 G1 X10 F600 M08 S5000 M03 T2 M06\n");
  EXPECT_EQ(kindsOf(steps),
            (std::vector<Kind>{Kind::kToolChange, Kind::kSpindle, Kind::kCoolant, Kind::kMove, Kind::kStop}));
  for (const auto& step : steps)
  {
    EXPECT_EQ(step.line, 2u) << step.describe();
  }
  EXPECT_EQ(steps[0].tool, 2);
  EXPECT_EQ(steps[1].spindle, gc::Spindle::kClockwise);
  EXPECT_DOUBLE_EQ(steps[1].spindle_rpm, 5000.0);
  EXPECT_TRUE(steps[2].coolant);
  EXPECT_DOUBLE_EQ(steps[3].move.end.x, 10.0);
  EXPECT_EQ(steps[4].describe(), "M00 program stop at line 2");
}

TEST(ProgramSteps, NothingAfterTheEndIsRead)
{
  // The line after M30 is not even valid G-code: reading it would throw.
  const auto steps = stepsOf("G21 G90\nG1 X1 F100\nM30\nG1 X1 X2\n");
  EXPECT_EQ(kindsOf(steps), (std::vector<Kind>{Kind::kMove, Kind::kEnd}));
  EXPECT_EQ(steps.back().m_code, 30);
  EXPECT_EQ(stepsOf("G1 X1 F100\nM02\nG1 X5\n").back().describe(), "M02 program end at line 2");
}

TEST(ProgramSteps, DwellsOptionalStopsAndSpindleChangesAreSteps)
{
  const auto steps = stepsOf("G21 G90\nG1 X1 F100\nG04 P0.5\nM01\nM03 S9000\nM05\nM09\n");
  EXPECT_EQ(kindsOf(steps),
            (std::vector<Kind>{Kind::kMove, Kind::kDwell, Kind::kOptionalStop, Kind::kSpindle, Kind::kSpindle}));
  EXPECT_DOUBLE_EQ(steps[1].dwell_s, 0.5);
  EXPECT_EQ(steps[1].describe(), "G04 dwell of 0.500 s at line 3");
  EXPECT_EQ(steps[3].spindle, gc::Spindle::kClockwise);
  EXPECT_EQ(steps[3].spindle_rpm, 9000.0);
  EXPECT_EQ(steps[4].spindle, gc::Spindle::kOff);
  // M09 with coolant already off changes nothing: no step.
  EXPECT_TRUE(steps[3].isMachineCommand());
  EXPECT_FALSE(steps[2].isMachineCommand());
}

TEST(ProgramSteps, AHaasDwellIsInMillisecondsWithoutADecimalPoint)
{
  gc::ParserOptions haas;
  haas.dialect = gc::Dialect::kHaas;
  EXPECT_DOUBLE_EQ(stepsOf("G04 P500\n", haas).front().dwell_s, 0.5);
  gc::ParserOptions linuxcnc;
  linuxcnc.dialect = gc::Dialect::kLinuxCnc;
  EXPECT_DOUBLE_EQ(stepsOf("G04 P2\n", linuxcnc).front().dwell_s, 2.0);
}
