// ToMachineFrame: goal coordinates given in any tf frame (the cell's `world`, a robot's base)
// brought into a machine's own frame (<tf_prefix>machine) with tf2. A goal with no frame, or
// already in the machine frame, is taken as it is; one whose frame has no transform into the machine frame is
// refused with tf2's own reason, before anything reaches the machine.
#pragma once

#include <geometry_msgs/Point.h>
#include <geometry_msgs/Pose.h>
#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <tf2_geometry_msgs/tf2_geometry_msgs.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <optional>
#include <string>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
/// \brief Transforms from a goal's frame into the machine frame. Listens to /tf and /tf_static
/// from construction on. Thread-safe (tf2_ros::Buffer is).
class ToMachineFrame
{
 public:
  /// One transform, or none when the goal is already in the machine frame.
  using Transform = std::optional<geometry_msgs::TransformStamped>;

  /// \param timeout_s how long a lookup waits for a transform that has not arrived yet.
  explicit ToMachineFrame(double timeout_s) : timeout_(timeout_s) {}

  /// \brief The latest transform from \p frame into \p machine; none when \p frame is empty or is
  /// \p machine.
  /// \param what names the goal's coordinates in the refusal ("points", "path").
  /// \throws ConfigError `<what> in frame "F" refused: no transform into "M": <tf2's reason>`.
  Transform lookup(const std::string& machine, const std::string& frame, const std::string& what)
  {
    if (frame.empty() || frame == machine)
    {
      return std::nullopt;
    }
    try
    {
      return buffer_.lookupTransform(machine, frame, ros::Time(0), ros::Duration(timeout_));
    }
    catch (const tf2::TransformException& e)
    {
      throw ConfigError(what + " in frame \"" + frame + "\" refused: no transform into \"" + machine +
                        "\": " + e.what());
    }
  }

  static geometry_msgs::Point apply(const Transform& transform, const geometry_msgs::Point& point)
  {
    if (!transform)
    {
      return point;
    }
    geometry_msgs::Point out;
    tf2::doTransform(point, out, *transform);
    return out;
  }

  static geometry_msgs::Pose apply(const Transform& transform, const geometry_msgs::Pose& pose)
  {
    if (!transform)
    {
      return pose;
    }
    geometry_msgs::Pose out;
    tf2::doTransform(pose, out, *transform);
    return out;
  }

 private:
  const double timeout_;
  tf2_ros::Buffer buffer_;
  tf2_ros::TransformListener listener_{buffer_};
};
}  // namespace cnc_bridge
