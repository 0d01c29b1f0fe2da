// at_controller_node when its links to sim_at_controller fail: the command link lost in the middle
// of a goal fails the goal with the link error and the node reconnects for the next goal; the
// report link lost makes the e-stop unknown, which refuses motion until the controller reports E0;
// the node killed mid-goal leaves the controller holding its last setpoint, and the node started
// again (respawn) runs the next goal.
#include <signal.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "at_test_support.h"
#include "process_kill.h"

using namespace at_test;
using process_kill::nodePid;

namespace
{
std::string node, ns, pid_file, command_log;

/// Setpoint lines ("feed pos feed pos feed pos") among \p lines.
size_t countSetpoints(const std::vector<std::string>& lines)
{
  return static_cast<size_t>(std::count_if(
      lines.begin(), lines.end(),
      [](const std::string& line)
      { return !line.empty() && (std::isdigit(static_cast<unsigned char>(line[0])) || line[0] == '-'); }));
}

struct AtControllerLink : ::testing::Test
{
  StateWatch state{ns + "/state"};
  FollowPathClient client{node + "/follow_path", false};
  void SetUp() override { waitUntilReady(client, state); }
};
}  // namespace

// The simulator closes the command connection at its 300th setpoint (fault script): the goal ends
// ABORTED with the link error, the controller got part of the path and no end of the operation;
// the node reconnects and the next goal runs to its end point.
TEST_F(AtControllerLink, CommandLinkLostMidGoalAbortsWithTheLinkErrorAndTheNextGoalRunsAfterReconnect)
{
  CommandLog received{command_log};
  const size_t mark = received.lines().size();
  const auto start = state.last().position;
  const uint64_t not_up_before = state.linkNotUpCount();
  client.sendGoal(lineGoal(start.x + 0.03, start.y, start.z, 0.02, ""));  // some 1550 setpoints
  ASSERT_TRUE(client.waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED) << client.getState().getText();
  const std::string text = client.getResult()->message;
  EXPECT_EQ(text.find("command link lost after "), 0u) << text;
  EXPECT_NE(text.find("127.0.0.1:23316"), std::string::npos) << text;  // the link error names the link
  EXPECT_LT(client.getResult()->setpoints, 1000u);
  const auto first = received.lines();
  const std::vector<std::string> of_first(first.begin() + static_cast<long>(mark), first.end());
  ASSERT_FALSE(of_first.empty());
  EXPECT_EQ(of_first.front(), "M1");
  EXPECT_GE(countSetpoints(of_first), 300u);
  EXPECT_LT(countSetpoints(of_first), 1000u);
  EXPECT_EQ(std::count(of_first.begin(), of_first.end(), "#"), 0);  // the operation never ended

  // Reconnected: the next goal (back to the start) runs whole on the new connection.
  ASSERT_TRUE(state.waitForLinkBackUp(not_up_before, 20.0)) << "link " << int(state.last().link);
  const size_t second_mark = received.lines().size();
  client.sendGoal(lineGoal(start.x, start.y, start.z, 0.02, ""));
  ASSERT_TRUE(client.waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << client.getState().getText();
  EXPECT_TRUE(state.waitFor(
      [&](const auto& s)
      {
        return std::fabs(s.position.x - start.x) <= 1.5e-6 && std::fabs(s.position.y - start.y) <= 1.5e-6 &&
               std::fabs(s.position.z - start.z) <= 1.5e-6;
      }))
      << state.last().position;
  const auto second = received.linesUntil(second_mark, "M0");
  ASSERT_GE(second.size(), 4u);
  EXPECT_EQ(second.front(), "M1");
  EXPECT_EQ(second[second.size() - 2], "#");
  EXPECT_EQ(countSetpoints(second), client.getResult()->setpoints);
}

// SIGHUP: the simulator closes the report connection and every new one. The e-stop becomes
// UNKNOWN and every motion request is refused, saying why, with nothing sent to the controller
// (set_auto, always allowed, is the barrier: it is all the controller receives). The next SIGHUP
// ends the outage: E0 arrives and motion is allowed again.
TEST_F(AtControllerLink, ReportLinkLossMakesTheEmergencyStopUnknownAndRefusesMotionUntilE0)
{
  CommandLog received{command_log};
  const size_t mark = received.lines().size();
  const auto start = state.last().position;
  const pid_t pid = process_kill::pidFromFile(pid_file);
  ASSERT_GT(pid, 0);
  ASSERT_EQ(kill(pid, SIGHUP), 0);
  ASSERT_TRUE(state.waitFor([](const auto& s) { return s.estop == cnc_bridge::MachineState::ESTOP_UNKNOWN; }))
      << int(state.last().estop);
  const std::string unknown = "the controller's emergency stop state is unknown";
  const auto jog = call<cnc_bridge::AtJog>(node + "/jog", jogRequest("x", 0.01));
  EXPECT_FALSE(jog.success);
  EXPECT_NE(jog.message.find(unknown), std::string::npos) << jog.message;
  const auto home = call<std_srvs::Trigger>(node + "/home");
  EXPECT_FALSE(home.success);
  EXPECT_NE(home.message.find(unknown), std::string::npos) << home.message;
  client.sendGoal(lineGoal(start.x + 0.01, start.y, start.z, 0.02, ""));
  ASSERT_TRUE(client.waitForResult(ros::Duration(10.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED);
  EXPECT_NE(client.getResult()->message.find(unknown), std::string::npos) << client.getResult()->message;
  EXPECT_TRUE(call<std_srvs::Trigger>(node + "/set_auto").success);
  EXPECT_EQ(received.linesUntil(mark, "A"), std::vector<std::string>{"A"});

  ASSERT_EQ(kill(pid, SIGHUP), 0);  // the outage ends: the next report connection gets E0
  ASSERT_TRUE(state.waitFor(
      [](const auto& s)
      { return s.estop == cnc_bridge::MachineState::ESTOP_OFF && s.link == cnc_bridge::MachineState::LINK_UP; },
      20.0))
      << int(state.last().estop);
  const auto again = call<cnc_bridge::AtJog>(node + "/jog", jogRequest("x", 0.0));
  EXPECT_TRUE(again.success) << again.message;
  EXPECT_TRUE(call<std_srvs::Trigger>(node + "/set_auto").success);
}

// Node death: the node killed (SIGKILL: no shutdown, no deceleration) in the middle of a goal.
// The controller receives no more setpoints and no end of the operation; it holds the last
// setpoint it received (the protocol has no host watchdog). The launch respawns the node, which
// reads the held position from the controller and runs the next goal. Last in this file: it
// replaces the node the tests above used.
TEST_F(AtControllerLink, NodeDeathStopsTheSetpointsTheControllerHoldsTheLastOneAndARespawnedNodeRunsTheNextGoal)
{
  CommandLog received{command_log};
  const size_t mark = received.lines().size();
  const auto start = state.last().position;
  client.sendGoal(lineGoal(start.x - 0.03, start.y, start.z, 0.02, ""));
  ASSERT_TRUE(state.waitFor([&](const auto& s) { return s.position.x < start.x - 0.005; }));
  const pid_t pid = nodePid(node);
  ASSERT_GT(pid, 0);
  ASSERT_EQ(kill(pid, SIGKILL), 0);
  // What was on its way arrives within the first window, nothing in the second.
  const auto windows = process_kill::countOverWindows([&] { return received.lines().size(); });
  EXPECT_EQ(windows.after_second, windows.after_first);
  const auto after_death = received.lines();
  // Long dead by now: a state stamped later comes from the respawned node (states are restamped
  // and published at ~state_rate).
  const ros::Time dead_by = ros::Time::now();
  const std::vector<std::string> of_goal(after_death.begin() + static_cast<long>(mark), after_death.end());
  EXPECT_EQ(std::count(of_goal.begin(), of_goal.end(), "#"), 0);
  ASSERT_GT(countSetpoints(of_goal), 100u);
  std::istringstream last(of_goal.back());
  long feed = 0, held_x = 0;
  ASSERT_TRUE(last >> feed >> held_x) << of_goal.back();

  // Respawned: the new node's state (from the controller's greeting on the new report link) is
  // the held setpoint, to the pulse.
  ASSERT_TRUE(state.waitFor(
      [&](const auto& s)
      {
        return s.header.stamp > dead_by && s.link == cnc_bridge::MachineState::LINK_UP && s.position_valid &&
               s.estop == cnc_bridge::MachineState::ESTOP_OFF;
      },
      30.0))
      << "no state from a respawned node";
  EXPECT_NE(nodePid(node), pid);
  EXPECT_NEAR(state.last().position.x, held_x * 1e-6, 1.5e-6);
  EXPECT_GT(state.last().position.x, start.x - 0.025);  // stopped part-way
  FollowPathClient next{node + "/follow_path", false};
  ASSERT_TRUE(next.waitForServer(ros::Duration(20.0)));
  next.sendGoal(lineGoal(start.x, start.y, start.z, 0.02, ""));
  ASSERT_TRUE(next.waitForResult(ros::Duration(20.0)));
  EXPECT_EQ(next.getState(), actionlib::SimpleClientGoalState::SUCCEEDED) << next.getState().getText();
  EXPECT_TRUE(state.waitFor([&](const auto& s) { return std::fabs(s.position.x - start.x) <= 1.5e-6; }))
      << state.last().position;
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_at_controller_link");
  ros::NodeHandle pnh("~");
  pnh.getParam("node", node);
  pnh.getParam("namespace", ns);
  pnh.getParam("pid_file", pid_file);
  pnh.getParam("command_log", command_log);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
