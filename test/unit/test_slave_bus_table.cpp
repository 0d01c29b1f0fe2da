// The slave table, the step queue and the bus counters of slave_bus_node, without ROS or a port.
#include <gtest/gtest.h>

#include <cmath>

#include <string>
#include <thread>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/slave_bus/bus_monitor.h"
#include "cnc_bridge/slave_bus/slave_table.h"
#include "cnc_bridge/slave_bus/step_queue.h"

namespace sb = cnc_bridge::slave_bus;
using cnc_bridge::ConfigError;
using cnc_bridge::Milliseconds;
using cnc_bridge::ProtocolError;

namespace
{
std::vector<sb::SlaveConfig> cell()
{
  return {{1, "x", sb::Role::kAxisX, sb::Encoding::kBigEndian16s, 1000.0},  // 1 unit = 1 mm
          {2, "y", sb::Role::kAxisY, sb::Encoding::kHundreds, 100.0},
          {4, "lamp", sb::Role::kGeneric, sb::Encoding::kBytes, 1.0}};
}

sb::SlaveTable table(std::vector<sb::SlaveConfig> slaves = cell(), size_t bus_size = 0)
{
  return sb::SlaveTable(std::move(slaves), bus_size, sb::WireFormat(), "~slaves", "~bus_size");
}

std::string configError(std::vector<sb::SlaveConfig> slaves, size_t bus_size = 0)
{
  try
  {
    table(std::move(slaves), bus_size);
  }
  catch (const ConfigError& e)
  {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(SlaveTable, BusSizeDefaultsToTheHighestAddressAndTablesAreChecked)
{
  const sb::SlaveTable t = table();
  EXPECT_EQ(t.busSize(), 4u);
  EXPECT_EQ(t.axisCount(), 2u);
  EXPECT_EQ(t.indexOf(4), 2);
  EXPECT_EQ(t.indexOf(3), -1);
  auto slaves = cell();
  slaves[1].address = 1;
  EXPECT_NE(configError(slaves).find("~slaves[1].address must be unique"), std::string::npos);
  slaves = cell();
  slaves[2].role = sb::Role::kAxisX;
  EXPECT_NE(configError(slaves).find("~slaves[2]: a second slave for the same axis"), std::string::npos);
  slaves = cell();
  slaves[2].name = "lamp/1";
  EXPECT_NE(configError(slaves).find("valid topic name part"), std::string::npos);
  slaves = cell();
  slaves[0].scale = 0.0;
  EXPECT_NE(configError(slaves).find("~slaves[0].scale"), std::string::npos);
  EXPECT_NE(configError(cell(), 3).find("~bus_size must be between the highest slave address (4)"), std::string::npos);
  EXPECT_NE(configError({}).find("non-empty"), std::string::npos);
}

TEST(SlaveTable, AxesAndToolsAndUnknownAddressesStartMotionGenericSlavesDoNot)
{
  const sb::SlaveTable t = table();
  EXPECT_TRUE(t.startsMotion(1));
  EXPECT_TRUE(t.startsMotion(3));  // nobody configured it: what it drives is unknown
  EXPECT_FALSE(t.startsMotion(4));
  EXPECT_EQ(sb::parseRole("axis_z"), sb::Role::kAxisZ);
  EXPECT_THROW(sb::parseRole("spindle"), ConfigError);
}

TEST(SlaveTable, CommandPayloadsScaleAxesAndCheckRanges)
{
  const sb::SlaveTable t = table();
  // -0.013 m on x: -13 device units of 1 mm, big-endian signed.
  EXPECT_EQ(t.commandPayload(0, {-0.013}, {}), (std::vector<uint8_t>{0xFF, 0xF3}));
  EXPECT_EQ(t.commandPayload(1, {1.23}, {}), (std::vector<uint8_t>{1, 23}));  // 123 = 1*100 + 23
  // Exact or refused: between two device units, NaN, infinite or beyond the encoding: never rounded,
  // wrapped or zeroed.
  for (const double bad : {-0.0125, 1e-7, std::nan(""), HUGE_VAL, -HUGE_VAL, 1e300, 2147483.648})
  {
    EXPECT_THROW(t.commandPayload(0, {bad}, {}), ProtocolError) << bad;
  }
  EXPECT_THROW(t.commandPayload(1, {1.2345}, {}), ProtocolError);
  EXPECT_THROW(t.commandPayload(1, {-0.01}, {}), ProtocolError);  // hundreds: unsigned
  for (const double bad : {std::nan(""), HUGE_VAL, 1e300, -1.0, 256.0, 2147483648.0, 0.5})
  {
    EXPECT_THROW(t.commandPayload(2, {bad}, {}), ProtocolError) << bad;  // bytes: 0..255 whole
  }
  EXPECT_EQ(t.commandPayload(2, {}, {9, 8}), (std::vector<uint8_t>{9, 8}));
  EXPECT_THROW(t.commandPayload(0, {40.0}, {}), ProtocolError);  // 40000 mm: beyond be16s
  EXPECT_THROW(t.commandPayload(0, {0.1, 0.2}, {}), ProtocolError);
  EXPECT_THROW(t.commandPayload(2, {1.5}, {}), ProtocolError);
  EXPECT_THROW(t.commandPayload(2, {1}, {1}), ProtocolError);
  EXPECT_THROW(t.commandPayload(2, {}, std::vector<uint8_t>(t.wire().max_data + 1, 0)), ProtocolError);
  // Replies come back in the same units.
  EXPECT_EQ(t.replyValues(0, {0xFF, 0xF4}), (std::vector<double>{-0.012}));
  EXPECT_EQ(t.replyValues(2, {7}), (std::vector<double>{7}));
  EXPECT_THROW(t.replyValues(1, {1, 200}), ProtocolError);  // lo must be below 100
}

TEST(SlaveTable, FramesAreCheckedAddressByAddress)
{
  const sb::SlaveTable t = table();
  const sb::StepPayloads step = t.framePayloads({{1, {1, 2}}, {4, {3}}});
  ASSERT_EQ(step.size(), 4u);
  EXPECT_EQ(step[0], (std::vector<uint8_t>{1, 2}));
  EXPECT_TRUE(step[1].empty());
  EXPECT_EQ(step[3], (std::vector<uint8_t>{3}));
  EXPECT_THROW(t.framePayloads({{5, {1}}}), ProtocolError);
  EXPECT_THROW(t.framePayloads({{0, {1}}}), ProtocolError);
  EXPECT_THROW(t.framePayloads({{1, {1}}, {1, {2}}}), ProtocolError);
}

// A long command delay: a step of commands never leaves by age within the test, so what leaves
// and when is decided by the queue's rules alone.
TEST(StepQueue, CommandsJoinTheLastStepOfCommandsWhileTheirSlotIsFree)
{
  sb::StepQueue queue(4, 10, Milliseconds(60000));
  ASSERT_TRUE(queue.pushCommand(0, {1}));  // x
  ASSERT_TRUE(queue.pushCommand(1, {2}));  // y joins
  ASSERT_TRUE(queue.pushCommand(0, {3}));  // x again: the next step
  EXPECT_EQ(queue.size(), 2u);
  sb::StepPayloads step;
  ASSERT_TRUE(queue.take(step, Milliseconds(0)));  // a step waits behind it: nothing more can join
  EXPECT_EQ(step, (sb::StepPayloads{{1}, {2}, {}, {}}));
  EXPECT_FALSE(queue.take(step, Milliseconds(0)));  // the last one still waits for company
  EXPECT_EQ(queue.size(), 1u);
}

TEST(StepQueue, AFrameLeavesAtOnceAndCommandsDoNotJoinStepsBeforeIt)
{
  sb::StepQueue queue(2, 10, Milliseconds(60000));
  ASSERT_TRUE(queue.pushCommand(0, {1}));
  ASSERT_TRUE(queue.pushFrame({{5}, {6}}));
  ASSERT_TRUE(queue.pushCommand(1, {2}));  // slot 1 of the first step is free, but a frame is between
  EXPECT_EQ(queue.size(), 3u);
  sb::StepPayloads step;
  ASSERT_TRUE(queue.take(step, Milliseconds(0)));
  EXPECT_EQ(step, (sb::StepPayloads{{1}, {}}));
  ASSERT_TRUE(queue.take(step, Milliseconds(0)));
  EXPECT_EQ(step, (sb::StepPayloads{{5}, {6}}));
}

TEST(StepQueue, AFullQueueRefusesAndAStepOfCommandsLeavesAfterTheDelay)
{
  sb::StepQueue queue(2, 2, Milliseconds(1));
  ASSERT_TRUE(queue.pushFrame({{1}, {}}));
  ASSERT_TRUE(queue.pushCommand(0, {2}));
  EXPECT_FALSE(queue.pushFrame({{3}, {}}));
  EXPECT_FALSE(queue.pushCommand(0, {4}));  // slot taken in the last step, and no room for another
  EXPECT_TRUE(queue.pushCommand(1, {5}));   // joins: no new step needed
  sb::StepPayloads step;
  ASSERT_TRUE(queue.take(step, Milliseconds(0)));
  // The command step leaves once its 1 ms has passed: take() waits for it (up to 10 s here).
  ASSERT_TRUE(queue.take(step, Milliseconds(10000)));
  EXPECT_EQ(step, (sb::StepPayloads{{2}, {5}}));
}

// The link went down: what waited is dropped, not sent when the link returns, and nothing is
// queued meanwhile, not even a command whose slot is free in a waiting step.
TEST(StepQueue, AClosedQueueDropsItsStepsAndRefusesPushesUntilOpened)
{
  sb::StepQueue queue(2, 10, Milliseconds(60000));
  EXPECT_TRUE(queue.isOpen());
  ASSERT_TRUE(queue.pushFrame({{1}, {}}));
  ASSERT_TRUE(queue.pushCommand(0, {2}));
  EXPECT_EQ(queue.close(), 2u);
  EXPECT_FALSE(queue.isOpen());
  EXPECT_EQ(queue.size(), 0u);
  EXPECT_FALSE(queue.pushFrame({{3}, {}}));
  EXPECT_FALSE(queue.pushCommand(1, {4}));
  sb::StepPayloads step;
  EXPECT_FALSE(queue.take(step, Milliseconds(0)));
  queue.open();
  ASSERT_TRUE(queue.pushFrame({{5}, {6}}));
  ASSERT_TRUE(queue.take(step, Milliseconds(0)));
  EXPECT_EQ(step, (sb::StepPayloads{{5}, {6}}));
  EXPECT_EQ(queue.close(), 0u);
}

TEST(StepQueue, StopWakesAWaitingTake)
{
  sb::StepQueue queue(2, 2, Milliseconds(1));
  bool taken = true;
  std::thread waiter(
      [&]
      {
        sb::StepPayloads step;
        taken = queue.take(step, Milliseconds(600000));
      });
  queue.stop();
  waiter.join();  // would wait ten minutes if stop() did not wake it
  EXPECT_FALSE(taken);
  EXPECT_TRUE(queue.stopped());
  EXPECT_TRUE(queue.pushFrame({{1}, {}}));
  sb::StepPayloads step;
  EXPECT_FALSE(queue.take(step, Milliseconds(0)));  // stopped for good
}

TEST(BusMonitor, CountsPerSlaveAndReportsTroubleOnlyWhileItGrows)
{
  const sb::SlaveTable t = table();
  sb::BusMonitor monitor(t);
  sb::BusSession::Stats session;
  session.steps_sent = 1;
  monitor.stepSent({{1}, {}, {}, {2}}, {1, 3}, session);  // x and the unconfigured 3 did not answer
  monitor.reply(2, true);
  monitor.reply(0, false);
  monitor.reply(-1, true);
  EXPECT_EQ(monitor.masterStatus({0, {3, 2}}),
            "slave bus master: " + std::string(sb::toString(sb::MasterStatus::kSlaveNoAnswer)) + " (address 2)");
  monitor.refused();
  auto report = monitor.report();
  EXPECT_TRUE(report.trouble);
  const auto value = [&](const std::string& key)
  {
    for (const auto& [k, v] : report.counters)
    {
      if (k == key)
        return static_cast<long>(v);
    }
    return -1L;
  };
  EXPECT_EQ(value("frames sent"), 1);
  EXPECT_EQ(value("timeouts"), 2);
  EXPECT_EQ(value("x: timeouts"), 1);
  EXPECT_EQ(value("x: payloads sent"), 1);
  EXPECT_EQ(value("lamp: payloads sent"), 1);
  EXPECT_EQ(value("x: undecodable replies"), 1);
  EXPECT_EQ(value("lamp: replies"), 1);
  EXPECT_EQ(value("y: failed reads (status 3)"), 1);
  EXPECT_EQ(value("replies from unconfigured addresses"), 1);
  EXPECT_EQ(value("refused inputs"), 1);
  // Nothing new: no trouble in the next report, the counters stay.
  report = monitor.report();
  EXPECT_FALSE(report.trouble);
  EXPECT_EQ(report.summary, "steps flowing");
  EXPECT_EQ(value("timeouts"), 2);
}
