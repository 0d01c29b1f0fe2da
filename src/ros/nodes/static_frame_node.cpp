// static_frame_node: publishes one static transform, for placing machines in the cell.
// Debian's tf2_ros package ships the library but not the static_transform_publisher program, so
// this is the same thing with the same arguments: x y z yaw pitch roll parent child (m, rad).
#include <ros/ros.h>
#include <tf2/LinearMath/Quaternion.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include <cstdlib>

int main(int argc, char** argv)
{
  ros::init(argc, argv, "static_frame", ros::init_options::AnonymousName);
  std::vector<std::string> args;
  ros::removeROSArgs(argc, argv, args);
  if (args.size() != 9)
  {
    ROS_FATAL("usage: static_frame_node x y z yaw pitch roll parent_frame child_frame");
    return 2;
  }
  tf2_ros::StaticTransformBroadcaster broadcaster;  // starts the node, so the clock is valid
  geometry_msgs::TransformStamped t;
  t.header.stamp = ros::Time::now();
  t.header.frame_id = args[7];
  t.child_frame_id = args[8];
  t.transform.translation.x = std::atof(args[1].c_str());
  t.transform.translation.y = std::atof(args[2].c_str());
  t.transform.translation.z = std::atof(args[3].c_str());
  tf2::Quaternion q;
  q.setRPY(std::atof(args[6].c_str()), std::atof(args[5].c_str()), std::atof(args[4].c_str()));
  t.transform.rotation.x = q.x();
  t.transform.rotation.y = q.y();
  t.transform.rotation.z = q.z();
  t.transform.rotation.w = q.w();
  broadcaster.sendTransform(t);
  ros::spin();
  return 0;
}
