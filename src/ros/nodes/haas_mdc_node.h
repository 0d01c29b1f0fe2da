// haas_mdc_node: its parameters, read in one place (haas_mdc_params.cpp) into the core's settings.
#pragma once

#include <ros/ros.h>

#include "cnc_bridge/mdc/mdc_session.h"

namespace cnc_bridge
{
/// \brief Reads every parameter of haas_mdc_node (docs/haas_mdc_node.md) into the session's
/// settings, the ~variables into its poll plan.
/// \throws ConfigError naming the parameter at fault.
mdc::MdcSettings haasMdcSettings(const ros::NodeHandle& pnh);
}  // namespace cnc_bridge
