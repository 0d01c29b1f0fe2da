// Helpers of the at_controller rostests: wait for a state that satisfies a condition (topic_watch.h),
// call a service, and follow a path goal. Every wait is on a message or a result, with a deadline.
#pragma once

#include <actionlib/client/simple_action_client.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <std_srvs/SetBool.h>
#include <std_srvs/Trigger.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "cnc_bridge/AtFollowPathAction.h"
#include "cnc_bridge/AtJog.h"
#include "cnc_bridge/AtSpindle.h"
#include "cnc_bridge/AtToolChange.h"
#include "cnc_bridge/MachineState.h"
#include "line_log.h"
#include "topic_watch.h"

namespace at_test
{
using FollowPathClient = actionlib::SimpleActionClient<cnc_bridge::AtFollowPathAction>;

/// The states of the machine, and waits for the latest one to satisfy a predicate.
class StateWatch : public topic_watch::TopicWatch<cnc_bridge::MachineState>
{
 public:
  explicit StateWatch(const std::string& topic) : TopicWatch(topic, 100) {}
  /// \returns true if a state satisfying \p predicate arrived within \p seconds.
  bool waitFor(const std::function<bool(const cnc_bridge::MachineState&)>& predicate, double seconds = 10.0)
  {
    return waitForLatest(predicate, seconds);
  }
  cnc_bridge::MachineState last() { return latest(); }
  /// States seen so far whose link was not UP (each change of the state is published).
  uint64_t linkNotUpCount() { return linkNotUp(all()); }
  /// \returns true if, within \p seconds, the link was seen not UP (after \p not_up_before such
  /// states) and is UP again.
  bool waitForLinkBackUp(uint64_t not_up_before, double seconds)
  {
    return Messages::waitFor(
        [&](const std::vector<cnc_bridge::MachineState>& states)
        { return linkNotUp(states) > not_up_before && states.back().link == cnc_bridge::MachineState::LINK_UP; },
        seconds);
  }

 private:
  static uint64_t linkNotUp(const std::vector<cnc_bridge::MachineState>& states)
  {
    return std::count_if(states.begin(), states.end(),
                         [](const cnc_bridge::MachineState& s) { return s.link != cnc_bridge::MachineState::LINK_UP; });
  }
};

template <class Service>
typename Service::Response call(const std::string& name, typename Service::Request request = {})
{
  EXPECT_TRUE(ros::service::waitForService(name, ros::Duration(10.0))) << name;
  Service service;
  service.request = request;
  EXPECT_TRUE(ros::service::call(name, service)) << name;
  return service.response;
}

inline cnc_bridge::AtJog::Request jogRequest(const std::string& axis, double feed)
{
  cnc_bridge::AtJog::Request request;
  request.axis = axis;
  request.feed_rate = feed;
  return request;
}

/// A straight nav_msgs/Path goal to (x, y, z) metres at \p feed m/s.
inline cnc_bridge::AtFollowPathGoal lineGoal(double x, double y, double z, double feed, const std::string& frame)
{
  cnc_bridge::AtFollowPathGoal goal;
  goal.path.header.frame_id = frame;
  geometry_msgs::PoseStamped pose;
  pose.pose.position.x = x;
  pose.pose.position.y = y;
  pose.pose.position.z = z;
  pose.pose.orientation.w = 1.0;
  goal.path.poses.push_back(pose);
  goal.feed_rate = feed;
  goal.coolant = cnc_bridge::AtFollowPathGoal::COOLANT_DEFAULT;
  goal.tool = -1;
  return goal;
}

/// The simulator's --command-log: every message the controller received, one per line. A test
/// marks the log, makes its requests, then sends a harmless barrier message: the command socket
/// keeps order, so once the barrier is in the log, everything sent before it is there too.
using CommandLog = line_log::LineLog;

/// Waits, before a test, until the action server is there and the controller reports its links
/// up, its position and a clear e-stop (fails the test otherwise).
inline void waitUntilReady(FollowPathClient& client, StateWatch& state)
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
}  // namespace at_test
