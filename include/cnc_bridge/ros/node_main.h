// One main() for every node: ros::init, the core's log routed to rosconsole, the node handle held
// for the node's whole life, a constructor error reported the same way by every node (one FATAL
// line "<node>: <what went wrong>", exit status 1; a missing required parameter also names the
// launch argument that sets it), and the callback threads the node needs.
#pragma once

#include <ros/ros.h>

#include <exception>

#include "cnc_bridge/ros/params.h"

namespace cnc_bridge
{
/// How a node's callbacks are served.
struct Spinning
{
  /// Callback threads; 1 serves everything in order on the main thread (ros::spin).
  unsigned threads = 1;
  /// Start serving before the node is constructed: for a constructor that waits on its own
  /// callbacks (a service of the node called while it connects). Otherwise callbacks start once
  /// the node is whole.
  bool before_construction = false;
};

/// \brief Runs `Node(ros::NodeHandle nh, ros::NodeHandle pnh)` until shutdown.
/// \returns the process exit status: 0, or 1 when the node could not be built (bad parameters, a
/// device that cannot be opened: the FATAL line says which and why).
template <class Node>
int runNode(int argc, char** argv, const char* name, Spinning spinning = {})
{
  ros::init(argc, argv, name);
  routeCoreLogToRosconsole();
  // Held here, outside the try block: a failing constructor must not shut ROS (and with it the
  // log that reports the failure) down before the FATAL line is written.
  ros::NodeHandle nh;
  try
  {
    if (spinning.threads <= 1)
    {
      Node node(nh, ros::NodeHandle("~"));
      ros::spin();
      return 0;
    }
    ros::AsyncSpinner spinner(spinning.threads);
    if (spinning.before_construction)
    {
      spinner.start();
    }
    Node node(nh, ros::NodeHandle("~"));
    if (!spinning.before_construction)
    {
      spinner.start();
    }
    ros::waitForShutdown();
    spinner.stop();  // no callback may run on a node being destroyed
  }
  catch (const params::MissingParameter& e)
  {
    // Each node's launch file (launch/<name>.launch) passes the parameter as the argument of the
    // same name: say which one to give.
    ROS_FATAL_STREAM(ros::this_node::getName() << ": " << e.what() << " Give it as the launch argument "
                                               << e.parameter() << ":=... of " << name << ".launch, in its params_file,"
                                               << " or as the private parameter _" << e.parameter() << ":=...");
    return 1;
  }
  catch (const std::exception& e)
  {
    ROS_FATAL_STREAM(ros::this_node::getName() << ": " << e.what());
    return 1;
  }
  return 0;
}
}  // namespace cnc_bridge
