// The scripted machine behind sim_haas_mdc (test/data/mdc/cell.mdcsim): its timeline, its replies
// in the Haas formats, writes, drops, and script errors. The node's rostest relies on all of this.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/mdc/mdc_monitor.h"
#include "sim/mdc/sim_machine.h"

using namespace cnc_bridge;
using namespace cnc_bridge::mdc;
using namespace std::chrono_literals;

namespace
{
SimMachine cell()
{
  std::ifstream in(MDC_TEST_DATA "/cell.mdcsim");
  EXPECT_TRUE(in);
  return SimMachine::fromScript(in, "cell.mdcsim");
}

SimMachine script(const std::string& text)
{
  std::istringstream in(text);
  return SimMachine::fromScript(in);
}
}  // namespace

TEST(MdcSim, AnswersInTheHaasFormats)
{
  SimMachine m = cell();
  const SimMachine::Clock::time_point t0{};
  m.start(t0);
  EXPECT_EQ(m.answer("?Q100", t0), "SERIAL NUMBER, 1234567");
  EXPECT_EQ(m.answer("?Q102\r", t0), "MODEL, VF2D");
  EXPECT_EQ(m.answer("?Q104", t0), "MODE, (MEM)");
  EXPECT_EQ(m.answer("?Q500", t0), "PROGRAM, O00110, IDLE, PARTS, 4523");
  EXPECT_EQ(m.answer("?Q500", t0 + 2s), "STATUS, BUSY");
  EXPECT_EQ(m.answer("?Q500", t0 + 3700ms), "PROGRAM, O00110, FEED HOLD, PARTS, 4523");
  EXPECT_EQ(m.answer("?Q500", t0 + 5100ms), "PROGRAM, O00110, IDLE, PARTS, 4524");
  EXPECT_EQ(m.answer("?Q500", t0 + 6600ms), "PROGRAM, O00110, ALARM ON, PARTS, 4524");
  EXPECT_EQ(m.answer("?Q104", t0 + 6600ms), "MODE, (MDI)");
  EXPECT_EQ(m.answer("?Q500", t0 + 9s + 5100ms), "PROGRAM, O00110, IDLE, PARTS, 4525");  // second loop
  EXPECT_EQ(m.answer("?Q201", t0 + 2s), "USING TOOL, 3");
  EXPECT_EQ(m.answer("?Q105", t0), "?, ?Q105");
  EXPECT_EQ(m.answer("hello", t0), "?, HELLO");
  EXPECT_EQ(m.answer("", t0), "");
  EXPECT_EQ(m.answer("?Q600 4006", t0), "MACRO, 20.000000");  // NGC: no variable number
  // Every reply the simulator gives is one our parser recognises.
  for (const char* query : {"?Q100", "?Q101", "?Q102", "?Q104", "?Q200", "?Q201", "?Q300", "?Q301", "?Q303", "?Q304",
                            "?Q402", "?Q403", "?Q500", "?Q600 5021"})
  {
    const auto reply = parseReply(m.answer(query, t0 + 20s));
    ASSERT_TRUE(reply) << query;
    EXPECT_TRUE(answers(*parseReadOnlyQuery(query), *reply)) << query << " -> " << reply->line;
  }
}

TEST(MdcSim, ClassicDialectNamesTheVariableAndSaysUnknown)
{
  // As the Classic serial port answers (test/data/mdc/classic_serial.mdcwire).
  SimMachine m = cell();
  m.setClassic(true);
  const SimMachine::Clock::time_point t0{};
  m.start(t0);
  EXPECT_EQ(m.answer("?Q600 4006", t0), "MACRO, 4006, 20.000000");
  EXPECT_EQ(m.answer("?Q105", t0), "UNKNOWN");
  EXPECT_EQ(m.answer("?Q600 x", t0), "UNKNOWN");
  const auto reply = parseReply(m.answer("?Q600 5021", t0 + 2500ms));
  ASSERT_TRUE(reply);
  EXPECT_TRUE(answers(macroQuery(5021), *reply));
  EXPECT_FALSE(answers(macroQuery(5022), *reply));
  EXPECT_EQ(macroOf(*reply).variable, 5021);
}

TEST(MdcSim, AxesMoveLinearlyAndWorkPositionsFollow)
{
  SimMachine m = cell();
  const SimMachine::Clock::time_point t0{};
  m.start(t0);
  // Phase 2 (1.5 s .. 3.5 s) moves X from 0 to 8 in: half way at 2.5 s.
  EXPECT_NEAR(macroOf(*parseReply(m.answer("?Q600 5021", t0 + 2500ms))).value, 4.0, 1e-6);
  EXPECT_NEAR(macroOf(*parseReply(m.answer("?Q600 5041", t0 + 2500ms))).value, 4.0 - 5.0, 1e-6);
  EXPECT_NEAR(macroOf(*parseReply(m.answer("?Q600 5023", t0 + 3500ms))).value, -3.0, 1e-6);
}

TEST(MdcSim, WritesOnlyToUserVariables)
{
  SimMachine m = cell();
  const SimMachine::Clock::time_point t0{};
  m.start(t0);
  EXPECT_EQ(m.answer("?E100 2.5", t0), "!");
  EXPECT_EQ(m.answer("?Q600 100", t0), "MACRO, 2.500000");
  EXPECT_EQ(m.answer("?E5021 1", t0), "?, ?E5021 1");
  EXPECT_EQ(m.answer("?E100", t0), "?, ?E100");
}

// The G54 work offset (#5221-#5223) is the script's `work`: read with Q600, written with ?E, and
// the work position (#5041-#5043) follows the written offset.
TEST(MdcSim, TheWorkOffsetReadsAndWritesAsTheG54Variables)
{
  SimMachine m = cell();  // work 5 4 -2
  const SimMachine::Clock::time_point t0{};
  m.start(t0);
  EXPECT_EQ(m.answer("?Q600 5221", t0), "MACRO, 5.000000");
  EXPECT_EQ(m.answer("?Q600 5223", t0), "MACRO, -2.000000");
  EXPECT_EQ(m.answer("?E5223 -1.5", t0), "!");
  EXPECT_EQ(m.answer("?Q600 5223", t0), "MACRO, -1.500000");
  EXPECT_EQ(m.answer("?Q600 5221", t0), "MACRO, 5.000000");
  const double z = macroOf(*parseReply(m.answer("?Q600 5023", t0 + 2500ms))).value;
  EXPECT_NEAR(macroOf(*parseReply(m.answer("?Q600 5043", t0 + 2500ms))).value, z + 1.5, 1e-6);
  EXPECT_EQ(m.answer("?E5224 1", t0), "?, ?E5224 1");  // G54 A: not in this machine
  EXPECT_EQ(m.answer("?E5220 1", t0), "?, ?E5220 1");
}

TEST(MdcSim, DropFiresOncePerDropPhase)
{
  SimMachine m = cell();
  const SimMachine::Clock::time_point t0{};
  m.start(t0);
  EXPECT_FALSE(m.dropDue(t0 + 1s));
  EXPECT_TRUE(m.dropDue(t0 + 8100ms));
  EXPECT_FALSE(m.dropDue(t0 + 8200ms));
  EXPECT_TRUE(m.dropDue(t0 + 17100ms));
}

TEST(MdcSim, MonitorFollowingTheSimulatorSeesEveryEvent)
{
  SimMachine m = cell();
  const SimMachine::Clock::time_point t0{};
  m.start(t0);
  MdcMonitor monitor;
  std::vector<CycleEventData::Type> seen;
  for (auto t = t0; t < t0 + 9s; t += 100ms)
  {
    for (const auto& e : monitor.apply(*parseReply(m.answer("?Q500", t)), t))
      seen.push_back(e.type);
  }
  EXPECT_EQ(seen, (std::vector<CycleEventData::Type>{CycleEventData::kCycleStart, CycleEventData::kCycleEnd}));
  EXPECT_EQ(monitor.status().parts, 4524);
}

TEST(MdcSim, ScriptErrorsNameTheLine)
{
  try
  {
    script("serial 1\nphase 1 status=IDLE\nphase x\n");
    FAIL();
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find(":3:"), std::string::npos) << e.what();
  }
  EXPECT_THROW(script("serial 1\n"), ConfigError);
  EXPECT_THROW(script("phase 1 colour=red\n"), ConfigError);
  EXPECT_THROW(script("phase 0 status=IDLE\n"), ConfigError);
  EXPECT_THROW(script("units furlong\nphase 1\n"), ConfigError);
  EXPECT_THROW(script("frobnicate\nphase 1\n"), ConfigError);
  EXPECT_NO_THROW(script("# comment only\nphase 1 status=IDLE # trailing comment\n"));
}

TEST(MdcSim, LastAndPreviousCycleTimesAreThoseOfTheCyclesThatEnded)
{
  // Two cycles per loop, 3 s and 2 s (a feed hold counts in the cycle), in a 9 s loop.
  SimMachine m = script(
      "phase 1 status=IDLE program=O1 parts=0\nphase 2 status=BUSY\nphase 1 status=FEED_HOLD\n"
      "phase 1 status=IDLE parts+=1\nphase 2 status=BUSY\nphase 2 status=IDLE parts+=1\n");
  const SimMachine::Clock::time_point t0{};
  m.start(t0);
  EXPECT_EQ(m.answer("?Q303", t0 + 3s), "LAST CYCLE, 000:00:00");  // none ended yet
  EXPECT_EQ(m.answer("?Q303", t0 + 4500ms), "LAST CYCLE, 000:00:03");
  EXPECT_EQ(m.answer("?Q304", t0 + 4500ms), "PREV CYCLE, 000:00:00");
  EXPECT_EQ(m.answer("?Q303", t0 + 7500ms), "LAST CYCLE, 000:00:02");
  EXPECT_EQ(m.answer("?Q304", t0 + 7500ms), "PREV CYCLE, 000:00:03");
  EXPECT_EQ(m.answer("?Q303", t0 + 9s + 4500ms), "LAST CYCLE, 000:00:03");  // next loop
  EXPECT_EQ(m.answer("?Q304", t0 + 9s + 4500ms), "PREV CYCLE, 000:00:02");
  EXPECT_EQ(m.answer("?Q303", t0 + 9s + 500ms), "LAST CYCLE, 000:00:02");
  // The cell's cycle: busy 2 s, feed hold 0.5 s, busy 1 s (whole seconds, as the control reports).
  SimMachine c = cell();
  c.start(t0);
  EXPECT_EQ(c.answer("?Q303", t0 + 5100ms), "LAST CYCLE, 000:00:03");
}

// `varN=VALUE` in a phase: the program sets the variable on entering the phase, every loop; a ?E
// write wins until the next phase that sets it (the cell's #500 handshake is made of this).
TEST(MdcSim, ScriptedVariablesFollowThePhasesAndAWriteWinsUntilTheNextSet)
{
  SimMachine m = script(
      "var 500 7\n"
      "phase 1.0 status=IDLE var500=0\n"
      "phase 1.0 status=BUSY\n"
      "phase 1.0 status=IDLE var500=1 var501=2.5\n");
  const SimMachine::Clock::time_point t0{};
  m.start(t0);
  EXPECT_EQ(m.answer("?Q600 500", t0 + 500ms), "MACRO, 0.000000");
  EXPECT_EQ(m.answer("?Q600 500", t0 + 1500ms), "MACRO, 0.000000");
  EXPECT_EQ(m.answer("?Q600 500", t0 + 2500ms), "MACRO, 1.000000");
  EXPECT_EQ(m.answer("?Q600 501", t0 + 2500ms), "MACRO, 2.500000");
  EXPECT_EQ(m.answer("?Q600 500", t0 + 3500ms), "MACRO, 0.000000");  // the next loop
  EXPECT_EQ(m.answer("?Q600 501", t0 + 3500ms), "MACRO, 2.500000");  // kept from the loop before
  EXPECT_EQ(m.answer("?E500 5", t0 + 3600ms), "!");
  EXPECT_EQ(m.answer("?Q600 500", t0 + 4500ms), "MACRO, 5.000000");
  EXPECT_EQ(m.answer("?Q600 500", t0 + 5500ms), "MACRO, 1.000000");  // set again by the script
  EXPECT_THROW(script("phase 1.0 var0=1\n"), ConfigError);
  EXPECT_THROW(script("phase 1.0 varx=1\n"), ConfigError);
  EXPECT_THROW(script("phase 1.0 var500=one\n"), ConfigError);
}
