// slave_bus_node when its master goes away and when it dies (see slave_bus_link.test), checked on
// the master's side with the simulator's delivery log: the master reports no e-stop, so the state
// says UNKNOWN; while the link is down a payload is refused and never reaches the master, not even
// when the link returns, and the next one does; the node killed while frames stream leaves the
// master receiving nothing more.
#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <signal.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include "cnc_bridge/BusFrame.h"
#include "cnc_bridge/MachineState.h"
#include "line_log.h"
#include "process_kill.h"
#include "topic_watch.h"

using cnc_bridge::MachineState;

namespace
{
std::string node, ns, pid_file, deliveries;
const double kWait = 20.0;  // seconds; generous for a loaded machine, healthy steps take ms

/// A frame with one payload for the x axis (slave 1, be16s device units).
cnc_bridge::BusFrame axisFrame(int16_t units)
{
  cnc_bridge::BusPayload payload;
  payload.address = 1;
  payload.data = {static_cast<uint8_t>(static_cast<uint16_t>(units) >> 8), static_cast<uint8_t>(units & 0xFF)};
  cnc_bridge::BusFrame frame;
  frame.payloads.push_back(payload);
  return frame;
}

/// The delivery log's line for that payload ("ADDRESS HEX").
std::string axisDelivery(int16_t units)
{
  char line[16];
  std::snprintf(line, sizeof line, "1 %04x", static_cast<unsigned>(static_cast<uint16_t>(units)));
  return line;
}

/// The node's "refused inputs" counter in a diagnostics message; -1 if it has none.
double refusedInputs(const diagnostic_msgs::DiagnosticArray& message)
{
  for (const auto& status : message.status)
  {
    for (const auto& kv : status.values)
    {
      if (status.name.find("slave bus") != std::string::npos && kv.key == "refused inputs")
      {
        return std::stod(kv.value);
      }
    }
  }
  return -1;
}

bool linkUp(const MachineState& s)
{
  return s.link == MachineState::LINK_UP;
}

struct SlaveBusLink : ::testing::Test
{
  topic_watch::TopicWatch<MachineState> state{ns + "/state"};
  topic_watch::TopicWatch<diagnostic_msgs::DiagnosticArray> diagnostics{"/diagnostics"};
  line_log::LineLog received{deliveries};
  ros::Publisher frames;

  void SetUp() override
  {
    frames = topic_watch::advertiseAndWait<cnc_bridge::BusFrame>(ns + "/bus/frame", kWait);
    ASSERT_GT(frames.getNumSubscribers(), 0u);
    ASSERT_TRUE(state.waitForLatest(linkUp, kWait)) << "link " << int(state.latest().link);
  }

  /// Publishes \p units for x and waits until the master handed it to the slave.
  bool delivered(int16_t units)
  {
    const size_t mark = received.lines().size();
    frames.publish(axisFrame(units));
    return !received.linesUntil(mark, axisDelivery(units), kWait).empty();
  }
};
}  // namespace

// The master has no e-stop to report: the state says UNKNOWN while the link is up and a frame
// moves the axis (the machine's own e-stop circuit is the protection).
TEST_F(SlaveBusLink, TheStateReportsTheEmergencyStopUnknownWhileTheLinkIsUp)
{
  ASSERT_TRUE(delivered(100));
  // The axis answered where it went: 100 device units at 10000 per metre (the example slaves).
  ASSERT_TRUE(state.waitForLatest([](const MachineState& s) { return std::fabs(s.position.x - 0.01) < 1e-9; }, kWait));
  const auto states = state.all();
  EXPECT_TRUE(std::all_of(states.begin(), states.end(),
                          [](const MachineState& s) { return s.estop == MachineState::ESTOP_UNKNOWN; }));
  EXPECT_TRUE(linkUp(state.latest()));
}

// SIGTERM: the simulated master closes its pty and the link goes down; roslaunch starts it again
// after respawn_delay. A payload published in the outage is refused (counted in diagnostics) and
// is not delivered when the link returns: the next payload, published after the return, reaches
// the master and nothing of the outage came before it.
TEST_F(SlaveBusLink, APayloadPublishedWhileTheLinkIsDownIsRefusedAndNotDeliveredWhenItReturns)
{
  const size_t mark = received.lines().size();
  const pid_t pid = process_kill::pidFromFile(pid_file);
  ASSERT_GT(pid, 0);
  ASSERT_TRUE(diagnostics.waitForLatest([](const auto& d) { return refusedInputs(d) >= 0; }, kWait));
  const double refused_before = refusedInputs(diagnostics.latest());
  ASSERT_EQ(kill(pid, SIGTERM), 0);
  ASSERT_TRUE(state.waitForLatest([](const MachineState& s) { return !linkUp(s); }, kWait));

  frames.publish(axisFrame(0x777));
  EXPECT_TRUE(diagnostics.waitForLatest([&](const auto& d) { return refusedInputs(d) == refused_before + 1; }, kWait))
      << "refused inputs " << refusedInputs(diagnostics.latest());
  EXPECT_FALSE(linkUp(state.latest())) << "the link returned before the payload was refused";

  ASSERT_TRUE(state.waitForLatest(linkUp, 30.0)) << "the link did not return";
  EXPECT_NE(process_kill::pidFromFile(pid_file), pid);  // a new simulated master
  ASSERT_TRUE(delivered(200));
  const auto since = received.lines();
  EXPECT_EQ(std::vector<std::string>(since.begin() + static_cast<long>(mark), since.end()),
            std::vector<std::string>{axisDelivery(200)});
}

// Node death: the node killed (SIGKILL) while frames stream (a publisher keeps sending every 20 ms
// through the death). The master receives nothing more. Last in this file: the node is gone.
TEST_F(SlaveBusLink, NodeDeathWhileFramesStreamLeavesTheMasterReceivingNothingMore)
{
  const pid_t pid = process_kill::nodePid(node);
  ASSERT_GT(pid, 0);
  const size_t mark = received.lines().size();
  std::atomic<bool> streaming{true};
  std::thread stream(
      [&]
      {
        for (int16_t units = 1000; streaming; ++units)
        {
          frames.publish(axisFrame(units));
          ros::WallDuration(0.02).sleep();  // the stream's pace, not a wait for anything
        }
      });
  const bool streamed = received.waitForMoreThan(mark + 5, kWait);
  EXPECT_TRUE(streamed) << "no frames reached the master";
  EXPECT_EQ(kill(pid, SIGKILL), 0);
  const auto windows = process_kill::countOverWindows([&] { return received.lines().size(); });
  streaming = false;
  stream.join();
  EXPECT_EQ(windows.after_second, windows.after_first) << "the master received payloads after the node died";
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_slave_bus_link");
  ros::NodeHandle pnh("~");
  pnh.getParam("node", node);
  pnh.getParam("namespace", ns);
  pnh.getParam("pid_file", pid_file);
  pnh.getParam("deliveries", deliveries);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
