// mtconnect_adapter_node's parameters (docs/mtconnect_adapter_node.md), each read, checked and
// returned as the core's settings.
#include "mtconnect_adapter_node.h"

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/ros/params.h"

namespace cnc_bridge
{
namespace
{
/// ~machines (names; uuids `<~cell>-<name>`) or, without it, the machines of ~cell_file.
std::vector<mtconnect::DeviceSpec> readDevices(const ros::NodeHandle& pnh)
{
  std::vector<std::string> names;
  if (pnh.hasParam("machines") && !pnh.getParam("machines", names))
    throw ConfigError(pnh.resolveName("machines") + " must be a list of machine names, e.g. [haas_vf2, laser]");
  if (!names.empty())
  {
    const std::string cell = pnh.param<std::string>("cell", "cell");
    std::vector<mtconnect::DeviceSpec> devices;
    for (const auto& name : names)
      devices.push_back({name, cell + "-" + name});
    return devices;
  }
  std::string cell_file;
  if (pnh.getParam("cell_file", cell_file) && !cell_file.empty())
    return mtconnect::cellDevices(cell_file);
  throw ConfigError("give " + pnh.resolveName("machines") + " (the machines to publish, e.g. [haas_vf2, laser]) or " +
                    pnh.resolveName("cell_file") + " (a cell file such as config/cell.yaml)");
}
}  // namespace

MtconnectAdapterSettings readMtconnectAdapterSettings(const ros::NodeHandle& pnh)
{
  MtconnectAdapterSettings s;
  s.devices = readDevices(pnh);
  // Checks the names as the agent will (XML names, each once) before anything listens.
  mtconnect::devicesXml(s.devices);
  // ~address: where agents connect; ~port: the adapter's TCP port (SHDR's usual 7878).
  s.adapter.address = pnh.param<std::string>("address", "0.0.0.0");
  s.adapter.port = params::tcpPort(pnh, "port", 7878, params::PortZero::kMeansAny);
  // ~heartbeat: s, announced to the agent in `* PONG`; it drops an adapter silent for longer.
  s.adapter.heartbeat = params::seconds(pnh, "heartbeat", 10.0);
  // ~write_timeout: s an agent may take to read our lines before it is dropped.
  s.adapter.write_timeout = params::seconds(pnh, "write_timeout", 2.0);
  // ~stale_after: s without a state message before the machine counts as lost (UNAVAILABLE).
  s.stale_after = params::positive(pnh, "stale_after", 5.0);
  // ~state_topics: {machine: topic} where a machine's state is not <machine>/state.
  std::map<std::string, std::string> topics;
  pnh.getParam("state_topics", topics);
  for (const auto& d : s.devices)
    s.state_topics[d.name] = topics.count(d.name) ? topics.at(d.name) : d.name + "/state";
  for (const auto& [name, topic] : topics)
  {
    if (!s.state_topics.count(name) || s.state_topics.at(name) != topic)
      throw ConfigError(pnh.resolveName("state_topics") + " names '" + name + "', which is not a machine of " +
                        pnh.resolveName("machines"));
  }
  // ~devices_file, ~agent_config_file: where to write the agent's Devices.xml and agent.cfg.
  s.devices_file = pnh.param<std::string>("devices_file", "");
  s.agent_config_file = pnh.param<std::string>("agent_config_file", "");
  s.agent_port = params::tcpPort(pnh, "agent_port", 5000);
  s.adapter_host =
      pnh.param<std::string>("adapter_host", s.adapter.address == "0.0.0.0" ? "127.0.0.1" : s.adapter.address);
  return s;
}
}  // namespace cnc_bridge
