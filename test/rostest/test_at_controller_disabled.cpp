// at_controller_node with ~enable_motion false (the default): every request that moves an axis or
// starts the spindle is refused and the refusal names the parameter and the run-time switch;
// harmless ones go through; motion switched on at run time is refused while the e-stop is unknown.
// The report link runs in server mode here (the simulator connects to the node).
#include "at_test_support.h"

using namespace at_test;

namespace
{
std::string node, ns, command_log;

void expectRefusedNamingTheParameter(bool success, const std::string& message)
{
  EXPECT_FALSE(success);
  EXPECT_NE(message.find(node + "/enable_motion"), std::string::npos) << message;
  EXPECT_NE(message.find(node + "/set_motion_enabled"), std::string::npos) << message;
}

struct AtControllerDisabled : ::testing::Test
{
  StateWatch state{ns + "/state"};
  CommandLog received{command_log};
  void SetUp() override
  {
    ASSERT_TRUE(
        state.waitFor([](const auto& s) { return s.link == cnc_bridge::MachineState::LINK_UP && s.position_valid; }));
  }

  /// Stops the spindle (always allowed) and returns what the controller received since \p mark,
  /// the stop included: a refused request must have added nothing before it.
  std::vector<std::string> receivedSinceThroughSpindleStop(size_t mark)
  {
    cnc_bridge::AtSpindle::Request stop;
    stop.speed = 0;
    EXPECT_TRUE(call<cnc_bridge::AtSpindle>(node + "/spindle", stop).success);
    return received.linesUntil(mark, "S0");
  }
};

const std::vector<std::string> kOnlyTheSpindleStop{"S0"};
}  // namespace

TEST_F(AtControllerDisabled, MotionServicesAreRefused)
{
  const size_t mark = received.lines().size();
  const auto jog = call<cnc_bridge::AtJog>(node + "/jog", jogRequest("x", 0.01));
  expectRefusedNamingTheParameter(jog.success, jog.message);
  const auto home = call<std_srvs::Trigger>(node + "/home");
  expectRefusedNamingTheParameter(home.success, home.message);
  cnc_bridge::AtSpindle::Request spin;
  spin.speed = 6000;
  const auto spindle = call<cnc_bridge::AtSpindle>(node + "/spindle", spin);
  expectRefusedNamingTheParameter(spindle.success, spindle.message);
  cnc_bridge::AtToolChange::Request tool;
  tool.tool = 2;
  tool.length = 0.05;
  const auto change = call<cnc_bridge::AtToolChange>(node + "/tool_change", tool);
  expectRefusedNamingTheParameter(change.success, change.message);
  EXPECT_EQ(receivedSinceThroughSpindleStop(mark), kOnlyTheSpindleStop) << "the controller received a refused request";
}

TEST_F(AtControllerDisabled, FollowPathIsRefused)
{
  FollowPathClient client(node + "/follow_path", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(10.0)));
  const size_t mark = received.lines().size();
  client.sendGoal(lineGoal(0.01, 0, 0, 0.01, ""));
  ASSERT_TRUE(client.waitForResult(ros::Duration(10.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED);
  expectRefusedNamingTheParameter(client.getResult()->success, client.getResult()->message);
  EXPECT_EQ(receivedSinceThroughSpindleStop(mark), kOnlyTheSpindleStop) << "the controller received a refused path";
}

TEST_F(AtControllerDisabled, HarmlessRequestsGoThrough)
{
  cnc_bridge::AtSpindle::Request stop;
  stop.speed = 0;  // stopping the spindle is always allowed
  const auto spindle = call<cnc_bridge::AtSpindle>(node + "/spindle", stop);
  EXPECT_TRUE(spindle.success) << spindle.message;
  EXPECT_EQ(spindle.message, "sent S0@");
  const auto mode = call<std_srvs::Trigger>(node + "/set_auto");
  EXPECT_TRUE(mode.success) << mode.message;
  EXPECT_TRUE(state.waitFor([](const auto& s) { return s.mode == cnc_bridge::MachineState::MODE_AUTO; }));
  std_srvs::SetBool::Request coolant;
  coolant.data = true;
  EXPECT_TRUE(call<std_srvs::SetBool>(node + "/coolant", coolant).success);
}

// Motion enabled at run time, but the controller has not reported its emergency stop (the
// simulator sends no E0 on connection): unknown is not clear, so motion is still refused, the
// refusal says why, and the controller receives nothing.
TEST_F(AtControllerDisabled, AnUnknownEmergencyStopBlocksMotion)
{
  EXPECT_EQ(state.last().estop, cnc_bridge::MachineState::ESTOP_UNKNOWN);
  std_srvs::SetBool::Request enable;
  enable.data = true;
  const auto switched = call<std_srvs::SetBool>(node + "/set_motion_enabled", enable);
  EXPECT_TRUE(switched.success);
  EXPECT_EQ(switched.message, "motion enabled by " + ros::this_node::getName());
  EXPECT_TRUE(
      state.waitFor([](const auto& s) { return s.message == "motion enabled by " + ros::this_node::getName(); }));
  const size_t mark = received.lines().size();
  const auto jog = call<cnc_bridge::AtJog>(node + "/jog", jogRequest("x", 0.01));
  EXPECT_FALSE(jog.success);
  EXPECT_NE(jog.message.find("emergency stop state is unknown"), std::string::npos) << jog.message;
  FollowPathClient client(node + "/follow_path", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(10.0)));
  client.sendGoal(lineGoal(0.01, 0, 0, 0.01, ""));
  ASSERT_TRUE(client.waitForResult(ros::Duration(10.0)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED);
  EXPECT_NE(client.getResult()->message.find("emergency stop state is unknown"), std::string::npos)
      << client.getResult()->message;
  EXPECT_EQ(receivedSinceThroughSpindleStop(mark), kOnlyTheSpindleStop) << "the controller received motion";
  enable.data = false;
  EXPECT_TRUE(call<std_srvs::SetBool>(node + "/set_motion_enabled", enable).success);
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_at_controller_disabled");
  ros::NodeHandle pnh("~");
  pnh.getParam("node", node);
  pnh.getParam("namespace", ns);
  pnh.getParam("command_log", command_log);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
