// mtconnect_node's parameters (docs/mtconnect_node.md), each read, checked and returned as the
// core's settings.
#include "mtconnect_node.h"

#include "cnc_bridge/ros/params.h"

namespace cnc_bridge
{
namespace
{
Milliseconds milliseconds(const ros::NodeHandle& pnh, const std::string& name, double fallback_s)
{
  const double s = params::positive(pnh, name, fallback_s);
  return Milliseconds(static_cast<long long>(s * 1000.0 + 0.5));
}
}  // namespace

MtconnectLinkSettings readMtconnectLink(const ros::NodeHandle& pnh)
{
  MtconnectLinkSettings link;
  // ~host (required): address of the MTConnect agent (a Haas NGC control, a PC running an agent);
  // ~tcp_port: the agent's HTTP port (cppagent's default 5000; a Haas NGC's built-in agent 8082);
  // ~connect_timeout: s allowed for a TCP connection.
  params::TcpLinkDefaults defaults;
  defaults.tcp_port = 5000;
  defaults.connect_timeout = 3.0;
  link.agent = params::tcpLink(pnh, defaults);
  // ~max_document_bytes: largest document (a probe, one part of the stream) accepted.
  int max_bytes = 16 << 20;
  pnh.param("max_document_bytes", max_bytes, max_bytes);
  if (max_bytes < 4096)
    throw ConfigError(pnh.resolveName("max_document_bytes") + " must be at least 4096");
  link.limits.max_document_bytes = static_cast<size_t>(max_bytes);
  return link;
}

mtconnect::FollowerSettings readFollowerSettings(const ros::NodeHandle& pnh)
{
  mtconnect::FollowerSettings s;
  // ~device: device name or uuid to follow; empty: the agent's first device.
  s.device = pnh.param<std::string>("device", "");
  // ~streaming: follow /sample as a multipart stream; false polls /sample every ~poll_period.
  s.streaming = pnh.param("streaming", true);
  // ~interval: s, the stream's interval (the agent sends what changed at most this often).
  s.interval = milliseconds(pnh, "interval", 0.1);
  // ~heartbeat: s, the agent's heartbeat on a quiet stream; no byte for heartbeat +
  // ~request_timeout drops the link.
  s.heartbeat = milliseconds(pnh, "heartbeat", 1.0);
  // ~poll_period: s between /sample polls when not streaming.
  s.poll_period = milliseconds(pnh, "poll_period", 0.5);
  // ~request_timeout: s an answer may take.
  s.request_timeout = milliseconds(pnh, "request_timeout", 5.0);
  // ~count: observations per document at most.
  int count = 1000;
  pnh.param("count", count, count);
  if (count < 1)
    throw ConfigError(pnh.resolveName("count") + " must be at least 1");
  s.count = static_cast<unsigned>(count);
  return s;
}

mtconnect::Mapping readMapping(const ros::NodeHandle& pnh)
{
  // ~mapping: {field: selector or [selectors]} over the standard's default (docs/mtconnect_node.md).
  XmlRpc::XmlRpcValue given;
  if (!pnh.getParam("mapping", given))
    return mtconnect::defaultMapping();
  const std::string name = pnh.resolveName("mapping");
  if (given.getType() != XmlRpc::XmlRpcValue::TypeStruct)
    throw ConfigError(name + " must be a dictionary {field: [selectors]}");
  mtconnect::Mapping overrides;
  for (auto& [field, value] : given)
  {
    auto& selectors = overrides[field];
    if (value.getType() == XmlRpc::XmlRpcValue::TypeString)
    {
      selectors.push_back(static_cast<std::string>(value));
      continue;
    }
    if (value.getType() != XmlRpc::XmlRpcValue::TypeArray)
      throw ConfigError(name + "/" + field + " must be a selector or a list of selectors");
    for (int i = 0; i < value.size(); ++i)
    {
      if (value[i].getType() != XmlRpc::XmlRpcValue::TypeString)
        throw ConfigError(name + "/" + field + " must list selectors as strings");
      selectors.push_back(static_cast<std::string>(value[i]));
    }
  }
  return mtconnect::mergeMapping(overrides);
}
}  // namespace cnc_bridge
