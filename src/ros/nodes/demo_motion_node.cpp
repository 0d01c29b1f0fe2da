// demo_motion_node: a machine with no device behind it that traces a circle, so the shared state
// layer (state, joint_states, tf, diagnostics), the URDF and rviz can be seen and tested on their
// own. Parameters: ~radius (m, 0.1), ~period (s per revolution, 4), ~center_x, ~center_y, ~z (m).
#include <ros/ros.h>

#include <cmath>

#include "cnc_bridge/ros/machine_state_publisher.h"
#include "cnc_bridge/ros/node_main.h"
#include "cnc_bridge/ros/params.h"

namespace cnc_bridge
{
class DemoMotionNode
{
 public:
  DemoMotionNode(ros::NodeHandle nh, ros::NodeHandle pnh) : state_(nh, pnh, "simulated")
  {
    radius_ = params::positive(pnh, "radius", 0.1);
    period_ = params::positive(pnh, "period", 4.0);
    pnh.param("center_x", center_x_, -0.38);
    pnh.param("center_y", center_y_, -0.2);
    pnh.param("z", z_, -0.3);
    start_ = ros::Time::now();
    state_.update(
        [&](MachineState& s)
        {
          s.link = MachineState::LINK_UP;
          s.mode = MachineState::MODE_AUTO;
          s.execution = MachineState::EXECUTION_ACTIVE;
          s.program = "demo circle";
          s.tool = 1;
          s.spindle_speed = 6000.0;
          s.work_offset_valid = true;
          s.work_offset.x = center_x_;
          s.work_offset.y = center_y_;
          s.work_offset.z = 0.0;
        });
    timer_ = nh.createTimer(ros::Duration(0.02), &DemoMotionNode::step, this);
  }

 private:
  void step(const ros::TimerEvent&)
  {
    const double angle = 2.0 * M_PI * (ros::Time::now() - start_).toSec() / period_;
    const double speed = 2.0 * M_PI * radius_ / period_;
    state_.update(
        [&](MachineState& s)
        {
          s.position_valid = true;
          s.position.x = center_x_ + radius_ * std::cos(angle);
          s.position.y = center_y_ + radius_ * std::sin(angle);
          s.position.z = z_;
          s.feed_rate = speed;
        });
  }

  MachineStatePublisher state_;
  double radius_, period_, center_x_, center_y_, z_;
  ros::Time start_;
  ros::Timer timer_;
};
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::DemoMotionNode>(argc, argv, "demo_motion_node");
}
