// What every node publishes, checked on the demo machine: the latched state, joint_states whose
// positions match the state, and the tf chain from the cell to the tool through the URDF.
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <tf2_ros/transform_listener.h>

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <set>
#include <vector>

#include "cnc_bridge/MachineState.h"

namespace
{
std::string ns, prefix;

template <class M>
boost::shared_ptr<const M> waitFor(const std::string& topic, double seconds = 10.0)
{
  return ros::topic::waitForMessage<M>(topic, ros::Duration(seconds));
}
}  // namespace

TEST(MachineState, LatchedStateDescribesTheMachine)
{
  const auto state = waitFor<cnc_bridge::MachineState>(ns + "/state");
  ASSERT_TRUE(state);
  EXPECT_EQ(state->machine, "demo_mill");
  EXPECT_EQ(state->header.frame_id, prefix + "machine");
  EXPECT_EQ(state->link, cnc_bridge::MachineState::LINK_UP);
  EXPECT_EQ(state->mode, cnc_bridge::MachineState::MODE_AUTO);
  EXPECT_EQ(state->execution, cnc_bridge::MachineState::EXECUTION_ACTIVE);
  EXPECT_EQ(state->tool, 1);
  EXPECT_TRUE(state->position_valid);
  // The demo traces a circle of 0.1 m around (-0.38, -0.2) at z = -0.3 (metres, not mm).
  EXPECT_NEAR(std::hypot(state->position.x + 0.38, state->position.y + 0.2), 0.1, 1e-6);
  EXPECT_NEAR(state->position.z, -0.3, 1e-9);
  // 2 pi r / T = 0.157 m/s
  EXPECT_NEAR(state->feed_rate, 2 * M_PI * 0.1 / 4.0, 1e-6);
}

TEST(MachineState, StateFollowsTheMovingMachine)
{
  // Each state published while the demo machine moves is newer than the last and places the tool
  // somewhere else on its circle. (The publishing rate is measured in bench/cell, not asserted.)
  std::mutex mutex;
  std::condition_variable arrived;
  std::vector<cnc_bridge::MachineState> states;
  ros::NodeHandle nh;
  auto sub = nh.subscribe<cnc_bridge::MachineState>(ns + "/state", 100,
                                                    [&](const cnc_bridge::MachineState::ConstPtr& state)
                                                    {
                                                      std::lock_guard<std::mutex> lock(mutex);
                                                      states.push_back(*state);
                                                      arrived.notify_all();
                                                    });
  std::unique_lock<std::mutex> lock(mutex);
  ASSERT_TRUE(arrived.wait_for(lock, std::chrono::seconds(10), [&] { return states.size() >= 10; }));
  std::set<std::pair<double, double>> positions;
  for (size_t i = 1; i < states.size(); ++i)
  {
    EXPECT_GE(states[i].header.stamp, states[i - 1].header.stamp) << "state " << i;
    EXPECT_NEAR(std::hypot(states[i].position.x + 0.38, states[i].position.y + 0.2), 0.1, 1e-6);
    positions.insert({states[i].position.x, states[i].position.y});
  }
  EXPECT_GE(positions.size(), 2u) << "the tool did not move across " << states.size() << " states";
}

TEST(MachineState, JointStatesCarryThePositionInMetres)
{
  const auto joints = waitFor<sensor_msgs::JointState>(ns + "/joint_states");
  ASSERT_TRUE(joints);
  ASSERT_EQ(joints->name.size(), 3u);
  EXPECT_EQ(joints->name[0], prefix + "x_axis");
  EXPECT_EQ(joints->name[1], prefix + "y_axis");
  EXPECT_EQ(joints->name[2], prefix + "z_axis");
  ASSERT_EQ(joints->position.size(), 3u);
  EXPECT_NEAR(std::hypot(joints->position[0] + 0.38, joints->position[1] + 0.2), 0.1, 1e-6);
  EXPECT_NEAR(joints->position[2], -0.3, 1e-9);
}

TEST(MachineState, TfGivesTheToolInTheMachineFrameAndUnderTheSpindle)
{
  tf2_ros::Buffer buffer;
  tf2_ros::TransformListener listener(buffer);
  const std::string machine = prefix + "machine", tool = prefix + "tool", base = prefix + "base",
                    head = prefix + "head", work = prefix + "work";
  ASSERT_TRUE(buffer.canTransform(machine, tool, ros::Time(0), ros::Duration(10.0)));
  const auto t = buffer.lookupTransform(machine, tool, ros::Time(0));
  EXPECT_NEAR(std::hypot(t.transform.translation.x + 0.38, t.transform.translation.y + 0.2), 0.1, 1e-3);
  EXPECT_NEAR(t.transform.translation.z, -0.3, 1e-6);

  ASSERT_TRUE(buffer.canTransform(machine, work, ros::Time(0), ros::Duration(5.0)));
  const auto w = buffer.lookupTransform(machine, work, ros::Time(0));
  EXPECT_NEAR(w.transform.translation.x, -0.38, 1e-9);

  // Through the URDF: the table carries machine zero, so the tool tip stays under the spindle
  // (x = y = 0 in the base frame) and coincides with the head's tip.
  ASSERT_TRUE(buffer.canTransform(base, tool, ros::Time(0), ros::Duration(10.0)));
  // One instant both tf sources (the node and robot_state_publisher) have published past: the
  // wait ends when the later of them has.
  const ros::Time instant = ros::Time::now();
  ASSERT_TRUE(buffer.canTransform(base, tool, instant, ros::Duration(10.0)));
  const auto in_base = buffer.lookupTransform(base, tool, instant);
  EXPECT_NEAR(in_base.transform.translation.x, 0.0, 0.03);
  EXPECT_NEAR(in_base.transform.translation.y, 0.0, 0.03);
  EXPECT_NEAR(in_base.transform.translation.z, 0.9 - 0.3, 1e-3);
  ASSERT_TRUE(buffer.canTransform(head, tool, instant, ros::Duration(10.0)));
  const auto tip = buffer.lookupTransform(head, tool, instant);
  EXPECT_NEAR(std::hypot(tip.transform.translation.x, tip.transform.translation.y), 0.0, 0.03);
}

int main(int argc, char** argv)
{
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_machine_state");
  ros::NodeHandle pnh("~");
  pnh.param<std::string>("namespace", ns, "");
  pnh.param<std::string>("tf_prefix", prefix, "");
  ros::AsyncSpinner spinner(1);
  spinner.start();
  return RUN_ALL_TESTS();
}
