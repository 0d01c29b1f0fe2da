// dnc_node's commanded position during a drip-feed (dnc_commanded_position.h).
#include "dnc_commanded_position.h"

#include <geometry_msgs/TransformStamped.h>

#include <sstream>

namespace cnc_bridge
{
CommandedPositionPublisher::CommandedPositionPublisher(ros::NodeHandle nh, const MachineStatePublisher& state)
    : program_frame_(state.frame("program")), tool_frame_(state.frame("commanded_tool"))
{
  // A block end at most as often as the state goes out, so a feed of short blocks does not flood
  // the topic and tf.
  const double rate = state.stateRate();
  period_ = ros::Duration(rate > 0 ? 1.0 / rate : 0.1);
  point_pub_ = nh.advertise<geometry_msgs::PointStamped>("dnc/commanded_position", 100);
}

void CommandedPositionPublisher::begin(const std::string& preamble)
{
  tracker_.reset();
  preamble_ = preamble;
  running_ = true;
  published_blocks_ = 0;
  unknown_since_ = true;
  last_publish_ = ros::Time();
}

void CommandedPositionPublisher::lineSent(const std::string& text)
{
  if (!preamble_.empty())
  {
    std::istringstream lines(preamble_);
    for (std::string line; std::getline(lines, line);)
      tracker_.feedLine(line);
    preamble_.clear();
  }
  tracker_.feedLine(text);
  refresh();
}

void CommandedPositionPublisher::refresh()
{
  if (!running_)
    return;
  if (!tracker_.known())
  {
    unknown_since_ = true;  // before the first motion block, or a block left the program's frame
    return;
  }
  const ros::Time now = ros::Time::now();
  // News at most once a period; an unchanged position once a period too, so that tf listeners
  // keep the frame while the control holds the feed.
  if (now - last_publish_ >= period_)
    publish(now);
}

void CommandedPositionPublisher::end()
{
  running_ = false;
  preamble_.clear();
}

void CommandedPositionPublisher::publish(const ros::Time& now)
{
  const gcode::Vec3 p = tracker_.metres();
  if (unknown_since_ || tracker_.motionBlocks() != published_blocks_)
  {
    geometry_msgs::PointStamped point;
    point.header.stamp = now;
    point.header.frame_id = program_frame_;
    point.point.x = p.x;
    point.point.y = p.y;
    point.point.z = p.z;
    point_pub_.publish(point);
    published_blocks_ = tracker_.motionBlocks();
    unknown_since_ = false;
  }
  geometry_msgs::Point at;
  at.x = p.x;
  at.y = p.y;
  at.z = p.z;
  tf_.sendTransform(translationTransform(now, program_frame_, tool_frame_, at));
  last_publish_ = now;
}
}  // namespace cnc_bridge
