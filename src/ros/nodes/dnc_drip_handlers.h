// dnc_node's drip-feed and backup protocols (docs/dnc_drip_feed.md): the `drip` and `backup`
// handlers of ~transfer and the services, the dnc/current_line topic, and state and feedback
// while a program is fed. The protocols themselves are the core's dnc::DripProtocols
// (include/cnc_bridge/dnc/drip_protocols.h); their parameters are read in dnc_params.cpp.
#pragma once

#include <ros/ros.h>

#include "cnc_bridge/dnc/dnc_settings.h"
#include "cnc_bridge/dnc/transfer_session.h"
#include "cnc_bridge/ros/machine_state_publisher.h"

namespace cnc_bridge
{
/// \brief Registers the protocols `drip` (send) and `backup` (receive) with \p session, with the
/// options \p settings (the ~drip_* and ~backup_* parameters); advertises ~pause, ~resume,
/// ~plan_drip and dnc/current_line.
/// \param state the node's state publisher (block = line being fed, PAUSED while held).
void registerDripProtocols(dnc::TransferSession& session, ros::NodeHandle nh, ros::NodeHandle pnh,
                           const dnc::DripSettings& settings, MachineStatePublisher& state);
}  // namespace cnc_bridge
