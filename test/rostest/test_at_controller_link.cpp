// at_controller_node when its links to sim_at_controller fail: the command link lost in the middle
// of a goal fails the goal with the link error and the node reconnects for the next goal; the
// report link lost makes the e-stop unknown, which refuses motion until the controller reports E0.
#include <signal.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "at_test_support.h"

using namespace at_test;

namespace
{
std::string node, ns, pid_file, command_log;

pid_t simulatorPid()
{
  std::ifstream in(pid_file);
  pid_t pid = 0;
  in >> pid;
  return pid;
}

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
  void SetUp() override
  {
    ASSERT_TRUE(client.waitForServer(ros::Duration(10.0)));
    ASSERT_TRUE(state.waitFor(
        [](const auto& s)
        {
          return s.link == cnc_bridge::MachineState::LINK_UP && s.position_valid &&
                 s.estop == cnc_bridge::MachineState::ESTOP_OFF;
        }))
        << "link " << int(state.last().link);
  }
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
  const pid_t pid = simulatorPid();
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
