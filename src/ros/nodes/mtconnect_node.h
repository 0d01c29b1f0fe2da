// mtconnect_node's parameters (docs/mtconnect_node.md), read in mtconnect_params.cpp into the
// core's settings.
#pragma once

#include <ros/ros.h>

#include <string>

#include "cnc_bridge/mtconnect/follower.h"
#include "cnc_bridge/mtconnect/http.h"
#include "cnc_bridge/mtconnect/machine_model.h"

namespace cnc_bridge
{
struct MtconnectLinkSettings
{
  std::string host;
  uint16_t tcp_port = 0;
  Milliseconds connect_timeout{3000};
  mtconnect::HttpLimits limits;
};

MtconnectLinkSettings readMtconnectLink(const ros::NodeHandle& pnh);
mtconnect::FollowerSettings readFollowerSettings(const ros::NodeHandle& pnh);
/// ~mapping: field -> selector or list of selectors, over the standard's default.
mtconnect::Mapping readMapping(const ros::NodeHandle& pnh);
}  // namespace cnc_bridge
