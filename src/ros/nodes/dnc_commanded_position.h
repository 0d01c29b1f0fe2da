// dnc_node's commanded position during a drip-feed (docs/dnc_drip_feed.md, "Commanded
// position"): the end point of the last motion block fed to the control, as
// dnc::CommandedPosition follows it, on `dnc/commanded_position` and as the tf frame
// <tf_prefix>program -> <tf_prefix>commanded_tool. The control buffers blocks, so this is where the
// program has told the tool to go, AHEAD of the tool; in the program's coordinates (the node does
// not know the work offset), hence the frame <tf_prefix>program. Published only while a feed runs
// and the position is known: nothing before the first motion block, after the feed, or for other
// transfers.
#pragma once

#include <geometry_msgs/PointStamped.h>
#include <ros/ros.h>
#include <tf2_ros/transform_broadcaster.h>

#include <string>

#include "cnc_bridge/dnc/commanded_position.h"
#include "cnc_bridge/ros/machine_state_publisher.h"

namespace cnc_bridge
{
/// \brief Publishes the commanded position of the feed that runs. Used from the one thread that
/// runs the feed (dnc_node runs one transfer at a time).
class CommandedPositionPublisher
{
 public:
  /// A new position is published at most at the state's rate (~state_rate).
  CommandedPositionPublisher(ros::NodeHandle nh, const MachineStatePublisher& state);

  /// \brief A feed begins: the last one is forgotten. \p preamble (restart blocks, '\n'-separated)
  /// goes out before the first line of the file and is followed with it.
  void begin(const std::string& preamble);
  /// \brief Line \p text of the file was written to the control whole.
  void lineSent(const std::string& text);
  /// \brief Called while the feed runs (progress, holds): publishes what the rate held back, and
  /// keeps the tf frame fresh while the control holds the feed.
  void refresh();
  /// \brief The feed ended (completed, cancelled, failed): nothing more is published.
  void end();

 private:
  void publish(const ros::Time& now);

  std::string program_frame_;
  std::string tool_frame_;
  ros::Duration period_;
  ros::Publisher point_pub_;
  tf2_ros::TransformBroadcaster tf_;
  dnc::CommandedPosition tracker_;
  std::string preamble_;  ///< restart blocks not yet followed (they go out before the first line)
  bool running_ = false;
  uint64_t published_blocks_ = 0;  ///< tracker_.motionBlocks() when last published
  bool unknown_since_ = true;      ///< unknown since the last point published: the next one is news
  ros::Time last_publish_;
};

}  // namespace cnc_bridge
