// The simulated machine of sim_mtconnect: a scripted machine's state (sim_haas_mdc's timeline) as
// the report the SHDR adapter core publishes, and the lines an agent reads from it: what the demo
// cell's mtconnect_mill tells the agent through a cycle.
#include <gtest/gtest.h>

#include <sstream>

#include "sim/mtconnect/sim_device.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mtconnect;
using namespace std::chrono_literals;
using cnc_bridge::mdc::SimMachine;

namespace
{
// 1 s idle, 2 s cutting (X to -10, Y to -5, Z to -4 at its end), 1 s held, 1 s idle with the part
// counted, 1 s in alarm.
const char* const kInchScript = R"(units inch
phase 1.0 mode=MEM status=IDLE program=O01001 tool=2 parts=40 x=0 y=0 z=0 spindle=0
phase 2.0 status=BUSY x=-10 y=-5 z=-4 spindle=9000
phase 1.0 status=FEED_HOLD
phase 1.0 status=IDLE parts+=1 spindle=0
phase 1.0 status=ALARM
)";

SimMachine machine(const std::string& text)
{
  std::istringstream in(text);
  SimMachine m = SimMachine::fromScript(in);
  m.start(SimMachine::Clock::time_point{});
  return m;
}

MachineReport at(const SimMachine& m, std::chrono::milliseconds t)
{
  return reportOf(m.stateAt(SimMachine::Clock::time_point{} + t), m.inch());
}

std::string joined(const std::vector<std::string>& lines)
{
  std::string out;
  for (const auto& l : lines)
    out += l + "\n";
  return out;
}
}  // namespace

TEST(MtconnectSim, IdleMachineIsReadyInAutomaticWithItsProgramAndCount)
{
  const MachineReport r = at(machine(kInchScript), 500ms);
  EXPECT_TRUE(r.link_up);
  EXPECT_EQ(r.view.mode, Mode::kAuto);
  EXPECT_EQ(r.view.execution, Execution::kReady);
  EXPECT_EQ(r.view.estop, Tristate::kOff);
  EXPECT_EQ(r.view.program, "O01001");
  EXPECT_EQ(r.view.part_count, 40);
  EXPECT_EQ(r.view.tool, 2);
  EXPECT_TRUE(r.message.empty());
}

TEST(MtconnectSim, PositionsInInchesBecomeMetresAndTheAgentMillimetres)
{
  const SimMachine m = machine(kInchScript);
  const MachineReport r = at(m, 2000ms);  // half way through the cut
  EXPECT_EQ(r.view.execution, Execution::kActive);
  ASSERT_TRUE(r.view.positionValid());
  EXPECT_NEAR(*r.view.position[0], -0.127, 1e-12);
  EXPECT_NEAR(*r.view.position[1], -0.0635, 1e-12);
  EXPECT_NEAR(*r.view.position[2], -0.0508, 1e-12);
  EXPECT_EQ(*r.view.spindle_rpm, 9000);
  EXPECT_FALSE(r.view.commandedValid());  // the script does not tell it: unknown, not 0
  ShdrDevice device("mill");
  const std::string text = joined(device.update(r));
  EXPECT_NE(text.find("mill:Xact|-127|"), std::string::npos) << text;
  EXPECT_NE(text.find("mill:exec|ACTIVE|"), std::string::npos) << text;
  EXPECT_NE(text.find("mill:Xcom|UNAVAILABLE|"), std::string::npos) << text;

  const SimMachine metric = machine("units mm\nphase 1.0 status=BUSY x=-300\nphase 1.0 status=IDLE\n");
  EXPECT_NEAR(*at(metric, 1500ms).view.position[0], -0.3, 1e-12);
}

TEST(MtconnectSim, ACycleEndsWithTheExecutionReadyAndThePartCounted)
{
  const SimMachine m = machine(kInchScript);
  ShdrDevice device("mill");
  device.update(at(m, 2000ms));  // cutting
  EXPECT_EQ(at(m, 3500ms).view.execution, Execution::kPaused);
  EXPECT_NE(joined(device.update(at(m, 3500ms))).find("mill:exec|INTERRUPTED"), std::string::npos);
  const std::string end = joined(device.update(at(m, 4500ms)));
  EXPECT_NE(end.find("mill:exec|READY"), std::string::npos) << end;
  EXPECT_NE(end.find("mill:partcount|41"), std::string::npos) << end;
}

TEST(MtconnectSim, AlarmIsAFaultWithItsWord)
{
  const MachineReport r = at(machine(kInchScript), 5500ms);
  EXPECT_EQ(r.view.execution, Execution::kAlarm);
  EXPECT_EQ(r.message, "ALARM");
  ShdrDevice device("mill");
  const std::string text = joined(device.update(r));
  EXPECT_NE(text.find("mill:system|FAULT||||ALARM"), std::string::npos) << text;
}

TEST(MtconnectSim, OtherModesAndAnUnknownStatus)
{
  const SimMachine m = machine(
      "phase 1.0 mode=MDI status=BUSY\nphase 1.0 mode=ZERO_RET\nphase 1.0 mode=EDIT\n"
      "phase 1.0 mode=JOG status=WHATEVER\n");
  EXPECT_EQ(at(m, 500ms).view.mode, Mode::kMdi);
  EXPECT_EQ(at(m, 1500ms).view.mode, Mode::kManual);
  EXPECT_EQ(at(m, 2500ms).view.mode, Mode::kEdit);
  EXPECT_EQ(at(m, 3500ms).view.mode, Mode::kManual);
  EXPECT_EQ(at(m, 3500ms).view.execution, Execution::kUnknown);
}
