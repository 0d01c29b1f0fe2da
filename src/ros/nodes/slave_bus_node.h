// slave_bus_node's parameters (docs/slave_bus_node.md), read in slave_bus_params.cpp into the core's
// settings of one bus.
#pragma once

#include <ros/ros.h>

#include "cnc_bridge/slave_bus/bus_runner.h"

namespace cnc_bridge
{
/// \brief Every parameter of slave_bus_node but the motion switch's (~enable_motion).
/// \throws ConfigError naming the parameter that is missing or wrong.
slave_bus::BusSettings readBusSettings(const ros::NodeHandle& pnh);
}  // namespace cnc_bridge
