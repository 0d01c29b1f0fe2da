// dnc_node's drip-feed and backup protocols (docs/dnc_drip_feed.md): the `drip` and `backup`
// handlers of ~transfer and the services, their parameters, the dnc/current_line topic, and state
// and feedback while a program is fed. The protocols themselves are the core library
// cnc_bridge_drip (include/cnc_bridge/dnc/).
#pragma once

#include <ros/ros.h>

#include "dnc_node.h"

namespace cnc_bridge
{
/// \brief Reads the ~drip_* and ~backup_* parameters and registers the protocols `drip` (send)
/// and `backup` (receive) with \p node.
/// \param serial the node's link settings (the drip-feed paces itself to their line rate).
/// \param state the node's state publisher (block = line being fed, PAUSED while held).
/// \param feedback_period action feedback at most this often (and on every hold/resume).
/// \throws ConfigError for an invalid parameter.
void registerDripProtocols(DncNode& node, ros::NodeHandle nh, ros::NodeHandle pnh, const SerialSettings& serial,
                           MachineStatePublisher& state, ros::Duration feedback_period);
}  // namespace cnc_bridge
