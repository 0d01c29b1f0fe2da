// Helpers of the rostests that kill a node or a simulator and check on the simulator's side that
// nothing more arrives: the process id of a ROS node (asked from the node itself) or of a
// simulator (from its pid file), and the two measurement windows after a death.
#pragma once

#include <ros/master.h>
#include <ros/network.h>
#include <ros/ros.h>
#include <sys/types.h>
#include <xmlrpcpp/XmlRpcClient.h>

#include <fstream>
#include <functional>
#include <string>

namespace process_kill
{
/// The process id of the node \p name, as its own XML-RPC server tells it (ROS slave API getPid);
/// 0 if it cannot be asked.
inline pid_t nodePid(const std::string& name)
{
  XmlRpc::XmlRpcValue args, result, uri;
  args[0] = ros::this_node::getName();
  args[1] = name;
  if (!ros::master::execute("lookupNode", args, result, uri, true))
  {
    return 0;
  }
  std::string host;
  uint32_t port = 0;
  if (!ros::network::splitURI(static_cast<std::string>(uri), host, port))
  {
    return 0;
  }
  XmlRpc::XmlRpcClient client(host.c_str(), static_cast<int>(port), "/");
  XmlRpc::XmlRpcValue caller, answer;
  caller[0] = ros::this_node::getName();
  if (!client.execute("getPid", caller, answer) || answer.getType() != XmlRpc::XmlRpcValue::TypeArray ||
      answer.size() < 3)
  {
    return 0;
  }
  return static_cast<int>(answer[2]);
}

/// The process id a simulator wrote to \p path (its --pid-file); 0 if there is none.
inline pid_t pidFromFile(const std::string& path)
{
  std::ifstream in(path);
  pid_t pid = 0;
  in >> pid;
  return pid;
}

/// What a peer had received (\p count: e.g. lines of its log) at the end of each window.
struct Windows
{
  size_t after_first = 0;
  size_t after_second = 0;
};

/// Measurement windows after a death: that nothing more arrives needs a span of time. What was on
/// its way arrives within the first (\p first_s), nothing in the second (\p second_s).
inline Windows countOverWindows(const std::function<size_t()>& count, double first_s = 0.3, double second_s = 0.5)
{
  Windows windows;
  ros::WallDuration(first_s).sleep();  // window: what was on its way arrives
  windows.after_first = count();
  ros::WallDuration(second_s).sleep();  // window: nothing more may arrive
  windows.after_second = count();
  return windows;
}
}  // namespace process_kill
