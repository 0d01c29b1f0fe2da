// slave_bus_node's parameters (slave_bus_node.h; docs/slave_bus_node.md, parameters), each read,
// checked and returned in the core's settings of the bus.
#include <algorithm>
#include <string>
#include <type_traits>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/ros/params.h"
#include "slave_bus_node.h"

namespace cnc_bridge
{
namespace
{
template <class T>
T member(XmlRpc::XmlRpcValue& item, const std::string& key, const T& fallback, const std::string& where)
{
  if (!item.hasMember(key))
  {
    return fallback;
  }
  XmlRpc::XmlRpcValue& value = item[key];
  if constexpr (std::is_same<T, double>::value)
  {
    if (value.getType() == XmlRpc::XmlRpcValue::TypeInt)
      return static_cast<int>(value);
    if (value.getType() == XmlRpc::XmlRpcValue::TypeDouble)
      return static_cast<double>(value);
  }
  else if constexpr (std::is_same<T, int>::value)
  {
    if (value.getType() == XmlRpc::XmlRpcValue::TypeInt)
      return static_cast<int>(value);
  }
  else
  {
    if (value.getType() == XmlRpc::XmlRpcValue::TypeString)
      return static_cast<std::string>(value);
  }
  throw ConfigError(where + "." + key + " has the wrong type");
}

/// ~framing and ~wirepacker_crc / ~max_payload: the master's dialect.
slave_bus::WireFormat wireFormat(const ros::NodeHandle& pnh)
{
  // ~wirepacker_crc: spec (CRC-8 over the length byte and the data, as the packet format documents
  // it) or library (data only, as the released ESP32_I2C_Slave library computes it): framed mode.
  const std::string crc = pnh.param<std::string>("wirepacker_crc", "spec");
  // ~max_payload: most data bytes of one WirePacker frame of the master (each slave's payload is
  // one I2C frame; in framed mode so is the whole step); 0 = 251 (spec) or 124 (library buffers).
  const int max_payload = pnh.param("max_payload", 0);
  if (max_payload < 0 || max_payload > static_cast<int>(slave_bus::kMaxPayload))
  {
    throw ConfigError(pnh.resolveName("max_payload") + " must be 0 (the default of ~wirepacker_crc) or 1.." +
                      std::to_string(slave_bus::kMaxPayload));
  }
  const slave_bus::WireCrc coverage =
      params::naming(pnh, "wirepacker_crc", [&] { return slave_bus::parseWireCrc(crc); });
  return slave_bus::WireFormat::of(coverage, static_cast<size_t>(max_payload));
}

/// One entry of ~slaves: {address, name, role, encoding, scale}.
slave_bus::SlaveConfig slaveEntry(XmlRpc::XmlRpcValue& item, const std::string& entry)
{
  if (item.getType() != XmlRpc::XmlRpcValue::TypeStruct)
  {
    throw ConfigError(entry + " is not a {address, name, role, ...} map");
  }
  slave_bus::SlaveConfig slave;
  const int address = member<int>(item, "address", 0, entry);
  slave.address = static_cast<uint8_t>(address >= 0 && address <= 255 ? address : 0);
  slave.name = member<std::string>(item, "name", "", entry);
  try
  {
    slave.role = slave_bus::parseRole(member<std::string>(item, "role", "generic", entry));
    slave.encoding = slave_bus::parseEncoding(member<std::string>(item, "encoding", "bytes", entry));
  }
  catch (const ConfigError& e)
  {
    throw ConfigError(entry + ": " + e.what());
  }
  slave.scale = member<double>(item, "scale", 1.0, entry);
  return slave;
}

/// ~slaves: list of {address, name, role (x|y|z|tool|generic), encoding (bytes|hundreds|be16|be16s),
/// scale (device units per metre, axes only)}; ~bus_size: slaves in every frame (the universal-CNC paper's master
/// firmware is built for a fixed count, e.g. 8); 0 (default): the highest configured address.
slave_bus::SlaveTable slaveTable(const ros::NodeHandle& pnh, const slave_bus::WireFormat& wire)
{
  XmlRpc::XmlRpcValue list;
  const std::string where = pnh.resolveName("slaves");
  if (!pnh.getParam("slaves", list))
  {
    throw ConfigError("Required parameter " + where + " not given.");
  }
  if (list.getType() != XmlRpc::XmlRpcValue::TypeArray)
  {
    throw ConfigError(where + " must be a non-empty list");
  }
  std::vector<slave_bus::SlaveConfig> slaves;
  for (int i = 0; i < list.size(); ++i)
  {
    slaves.push_back(slaveEntry(list[i], where + "[" + std::to_string(i) + "]"));
  }
  const int bus_size = pnh.param("bus_size", 0);
  return slave_bus::SlaveTable(std::move(slaves), static_cast<size_t>(std::max(0, bus_size)), wire, where,
                               pnh.resolveName("bus_size"));
}
}  // namespace

slave_bus::BusSettings readBusSettings(const ros::NodeHandle& pnh)
{
  // ~port (required), ~baud (115200), ~data_bits, ~parity, ~stop_bits, ~flow_control: the master's
  // serial line (a device, or a device server's tcp:// or rfc2217:// address).
  const LinkSettings link = params::serialLink(pnh, 115200);
  // ~framing: raw (the universal-CNC paper's bytes, for its stock master firmware) or framed (every frame in a
  // WirePacker frame with CRC-8, both directions; recommended where the firmware supports it).
  const slave_bus::Framing framing =
      params::naming(pnh, "framing", [&] { return slave_bus::parseFraming(pnh.param<std::string>("framing", "raw")); });
  slave_bus::BusSettings settings(slaveTable(pnh, wireFormat(pnh)));
  settings.link = link;
  settings.framing = framing;
  // ~max_queued_steps: steps waiting for the link; more are refused (and counted), not dropped
  // silently. ~command_delay (s): a step of queued commands leaves this long after its first
  // command, so that commands published together (x, y, then the tool) travel in one frame.
  settings.max_queued_steps = static_cast<size_t>(std::max(1, pnh.param("max_queued_steps", 100)));
  settings.command_delay = params::seconds(pnh, "command_delay", 0.005);
  // ~reply_timeout (s): how long a slave that got a payload has to answer before it counts a timeout.
  settings.reply_timeout = params::seconds(pnh, "reply_timeout", 0.5);
  // ~resync_gap (s): a partial uplink record followed by this much silence is dropped.
  settings.resync_gap = params::seconds(pnh, "resync_gap", 0.05);
  return settings;
}
}  // namespace cnc_bridge
