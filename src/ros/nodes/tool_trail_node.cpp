// tool_trail_node: the recent tool positions of one machine as a nav_msgs/Path, so rviz (whose TF
// display draws no trail) and bags show where the tool went on every machine, whatever its node.
// Subscribes to the machine's `state` (position in <tf_prefix>machine, metres) and publishes
// `tool_path` (latched) in the same frame: a point whenever the tool has moved ~min_distance, at
// most ~max_points of them (the oldest dropped), published at most ~publish_rate times a second.
// With ~label it also publishes `label` (visualization_msgs/Marker, latched): the machine's name
// as text above its model, so a cell of identical models shows which machine is which.
#include <nav_msgs/Path.h>
#include <ros/ros.h>
#include <visualization_msgs/Marker.h>

#include <cmath>
#include <deque>

#include "cnc_bridge/MachineState.h"
#include "cnc_bridge/ros/node_main.h"

namespace cnc_bridge
{
class ToolTrailNode
{
 public:
  ToolTrailNode(ros::NodeHandle nh, ros::NodeHandle pnh)
  {
    std::string prefix;
    // ~tf_prefix: prefix of the machine's frames; the trail is in <tf_prefix>machine.
    pnh.param<std::string>("tf_prefix", prefix, "");
    frame_ = prefix + "machine";
    // ~max_points: poses kept; the oldest go first.
    max_points_ = static_cast<size_t>(std::max(2, pnh.param("max_points", 500)));
    // ~min_distance: m the tool must move before a new pose is added.
    min_distance_ = pnh.param("min_distance", 0.0005);
    // ~publish_rate: Hz, the most often the trail is published (only when it changed).
    const double rate = pnh.param("publish_rate", 2.0);
    pub_ = nh.advertise<nav_msgs::Path>("tool_path", 1, true);
    sub_ = nh.subscribe("state", 10, &ToolTrailNode::onState, this);
    timer_ = nh.createTimer(ros::Duration(1.0 / std::max(rate, 0.1)), &ToolTrailNode::publish, this);
    // ~label: text shown above the machine (its name); empty: no label. ~label_height: m above
    // <tf_prefix>base; ~label_size: m, the height of the letters.
    const std::string label = pnh.param<std::string>("label", "");
    if (!label.empty())
    {
      label_pub_ = nh.advertise<visualization_msgs::Marker>("label", 1, true);
      label_pub_.publish(
          labelMarker(label, prefix + "base", pnh.param("label_height", 2.0), pnh.param("label_size", 0.25)));
    }
  }

 private:
  static visualization_msgs::Marker labelMarker(const std::string& text, const std::string& frame, double height,
                                                double size)
  {
    visualization_msgs::Marker marker;
    marker.header.frame_id = frame;  // stamp 0: rviz draws it at the latest transform
    marker.ns = "label";
    marker.type = visualization_msgs::Marker::TEXT_VIEW_FACING;
    marker.action = visualization_msgs::Marker::ADD;
    marker.pose.position.z = height;
    marker.pose.orientation.w = 1.0;
    marker.scale.z = size;
    marker.color.r = marker.color.g = marker.color.b = marker.color.a = 1.0f;
    marker.text = text;
    marker.frame_locked = true;
    return marker;
  }

  void onState(const MachineState& state)
  {
    if (!state.position_valid)
    {
      return;
    }
    const auto& p = state.position;
    if (!poses_.empty())
    {
      const auto& last = poses_.back().pose.position;
      if (std::hypot(p.x - last.x, p.y - last.y, p.z - last.z) < min_distance_)
      {
        return;
      }
    }
    geometry_msgs::PoseStamped pose;
    pose.header.stamp = state.header.stamp.isZero() ? ros::Time::now() : state.header.stamp;
    pose.header.frame_id = frame_;
    pose.pose.position = p;
    pose.pose.orientation.w = 1.0;
    poses_.push_back(pose);
    if (poses_.size() > max_points_)
    {
      poses_.pop_front();
    }
    changed_ = true;
  }

  void publish(const ros::TimerEvent&)
  {
    if (!changed_)
    {
      return;
    }
    changed_ = false;
    nav_msgs::Path path;
    path.header.stamp = poses_.back().header.stamp;
    path.header.frame_id = frame_;
    path.poses.assign(poses_.begin(), poses_.end());
    pub_.publish(path);
  }

  std::string frame_;
  size_t max_points_ = 500;
  double min_distance_ = 0.0005;
  std::deque<geometry_msgs::PoseStamped> poses_;  // callbacks and timer share the one spinner thread
  bool changed_ = false;
  ros::Publisher pub_;
  ros::Publisher label_pub_;
  ros::Subscriber sub_;
  ros::Timer timer_;
};
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  return cnc_bridge::runNode<cnc_bridge::ToolTrailNode>(argc, argv, "tool_trail");
}
