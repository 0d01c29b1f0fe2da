// mtconnect_node's parameters (docs/mtconnect_node.md), read in mtconnect_params.cpp into the
// core's settings.
#pragma once

#include <ros/ros.h>

#include <string>

#include "cnc_bridge/mtconnect/follower.h"
#include "cnc_bridge/mtconnect/http.h"
#include "cnc_bridge/mtconnect/machine_model.h"
#include "cnc_bridge/transport/link_factory.h"

namespace cnc_bridge
{
struct MtconnectLinkSettings
{
  LinkSettings agent;  ///< the agent's HTTP port (a TCP link)
  mtconnect::HttpLimits limits;
};

MtconnectLinkSettings readMtconnectLink(const ros::NodeHandle& pnh);
mtconnect::FollowerSettings readFollowerSettings(const ros::NodeHandle& pnh);
/// ~mapping: field -> selector or list of selectors, over the standard's default.
mtconnect::Mapping readMapping(const ros::NodeHandle& pnh);
}  // namespace cnc_bridge
