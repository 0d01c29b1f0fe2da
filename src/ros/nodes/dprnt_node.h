// dprnt_node: its parameters, read in one place (dprnt_params.cpp) into the core's settings.
#pragma once

#include <ros/ros.h>

#include "cnc_bridge/dprnt/settings.h"

namespace cnc_bridge
{
/// \brief Reads every parameter of dprnt_node (docs/dprnt_node.md).
/// \throws ConfigError naming the parameter at fault.
dprnt::DprntSettings dprntSettings(const ros::NodeHandle& pnh);
}  // namespace cnc_bridge
