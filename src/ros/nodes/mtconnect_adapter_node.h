// mtconnect_adapter_node's parameters (docs/mtconnect_adapter_node.md), read in
// mtconnect_adapter_params.cpp into the core's settings.
#pragma once

#include <ros/ros.h>

#include <map>
#include <string>
#include <vector>

#include "cnc_bridge/mtconnect/shdr.h"
#include "cnc_bridge/mtconnect/shdr_adapter.h"

namespace cnc_bridge
{
struct MtconnectAdapterSettings
{
  mtconnect::AdapterSettings adapter;
  std::vector<mtconnect::DeviceSpec> devices;
  std::map<std::string, std::string> state_topics;  ///< device -> its MachineState topic
  double stale_after = 5.0;                         ///< s without a state: the machine counts as lost
  std::string devices_file;                         ///< write Devices.xml here ("" not)
  std::string agent_config_file;                    ///< write an agent.cfg here ("" not)
  uint16_t agent_port = 5000;                       ///< the agent's HTTP port, for agent_config_file
  std::string adapter_host;                         ///< how the agent reaches this adapter
};

MtconnectAdapterSettings readMtconnectAdapterSettings(const ros::NodeHandle& pnh);
}  // namespace cnc_bridge
