// Parameter helpers (see params.h).
#include "cnc_bridge/ros/params.h"

#include <cmath>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace params
{
MissingParameter::MissingParameter(const ros::NodeHandle& pnh, const std::string& name, const std::string& alternative)
    : ConfigError("Required parameter " + pnh.resolveName(name) + " not given" +
                  (alternative.empty() ? "" : " (" + alternative + ")") + "."),
      parameter_(name)
{
}

double positive(const ros::NodeHandle& pnh, const std::string& name, double fallback)
{
  double value = fallback;
  pnh.param(name, value, fallback);
  if (!(value > 0.0) || !std::isfinite(value))
  {
    ROS_WARN_STREAM(pnh.resolveName(name) << " must be positive, not " << value << "; using " << fallback);
    value = fallback;
  }
  return value;
}

namespace
{
double limitNumber(const XmlRpc::XmlRpcValue& value, const std::string& where)
{
  if (value.getType() == XmlRpc::XmlRpcValue::TypeInt)
  {
    return static_cast<int>(const_cast<XmlRpc::XmlRpcValue&>(value));
  }
  if (value.getType() == XmlRpc::XmlRpcValue::TypeDouble)
  {
    const double number = static_cast<double>(const_cast<XmlRpc::XmlRpcValue&>(value));
    if (std::isfinite(number))
    {
      return number;
    }
  }
  throw ConfigError(where + ": a bound must be a finite number of metres");
}
}  // namespace

SoftLimits softLimits(const ros::NodeHandle& pnh, const std::string& name)
{
  SoftLimits limits;
  limits.setting = pnh.resolveName(name);
  XmlRpc::XmlRpcValue table;
  if (!pnh.getParam(name, table))
  {
    return limits;  // not set: no soft limits
  }
  const std::string form = " (give {x: [min, max], y: [min, max], z: [min, max]} in m; an axis may be left out)";
  if (table.getType() != XmlRpc::XmlRpcValue::TypeStruct)
  {
    throw ConfigError(limits.setting + " is not a dictionary" + form);
  }
  for (auto& [key, range] : table)
  {
    const std::string where = limits.setting + "/" + key;
    const int axis = key == "x" ? 0 : (key == "y" ? 1 : (key == "z" ? 2 : -1));
    if (axis < 0)
    {
      throw ConfigError(where + ": unknown axis (x, y or z)" + form);
    }
    if (range.getType() != XmlRpc::XmlRpcValue::TypeArray || range.size() != 2)
    {
      throw ConfigError(where + " is not [min, max]" + form);
    }
    const double low = limitNumber(range[0], where);
    const double high = limitNumber(range[1], where);
    if (!(low <= high))
    {
      throw ConfigError(where + ": min " + std::to_string(low) + " is above max " + std::to_string(high));
    }
    limits.axes[static_cast<size_t>(axis)] = std::make_pair(low, high);
  }
  return limits;
}

namespace
{
/// An integer parameter that must lie in \p low..\p high; \p fallback when not set.
unsigned boundedInt(const ros::NodeHandle& pnh, const std::string& name, int fallback, int low, int high)
{
  int value = fallback;
  pnh.param(name, value, fallback);
  if (value < low || value > high)
  {
    throw ConfigError(pnh.resolveName(name) + " must be " + std::to_string(low) + ".." + std::to_string(high) +
                      ", not " + std::to_string(value));
  }
  return static_cast<unsigned>(value);
}
}  // namespace

SerialSettings serialSettings(const ros::NodeHandle& pnh, unsigned default_baud)
{
  SerialSettings settings;
  // ~port: serial device, e.g. /dev/ttyUSB0, or a device server's port: tcp://host:port (raw TCP),
  // rfc2217://host:port (Telnet COM Port Control).
  settings.device = required<std::string>(pnh, "port");
  naming(pnh, "port", [&] { return parseSerialAddress(settings.device); });
  int baud = static_cast<int>(default_baud);
  // ~baud: bits per second (Haas setting 11).
  pnh.param("baud", baud, baud);
  if (baud <= 0)
  {
    throw ConfigError(pnh.resolveName("baud") + " must be positive, not " + std::to_string(baud));
  }
  settings.baud = static_cast<unsigned>(baud);
  // ~data_bits: 7 or 8 (Haas setting 37).
  settings.data_bits = boundedInt(pnh, "data_bits", 8, 5, 8);
  // ~parity: none, even or odd (Haas setting 12).
  settings.parity = naming(pnh, "parity", [&] { return parseParity(pnh.param<std::string>("parity", "none")); });
  // ~stop_bits: 1 or 2 (Haas setting 13).
  settings.stop_bits = boundedInt(pnh, "stop_bits", 1, 1, 2);
  // ~flow_control: none, xonxoff or rtscts.
  settings.flow_control =
      naming(pnh, "flow_control", [&] { return parseFlowControl(pnh.param<std::string>("flow_control", "none")); });
  // ~wire_trace: a folder; when set, every byte of the line, both ways, goes to a trace file there
  // (one per opening of the line, at most 16 MiB each; `cnc_dnc replay` plays one back).
  pnh.param<std::string>("wire_trace", settings.wire_trace.dir, "");
  settings.validate();
  return settings;
}

LinkSettings serialLink(const ros::NodeHandle& pnh, unsigned default_baud, InputOnOpen on_open)
{
  return LinkSettings::serialLine(serialSettings(pnh, default_baud), on_open);
}

LinkSettings tcpLink(const ros::NodeHandle& pnh, const TcpLinkDefaults& defaults)
{
  // ~host: the control's (agent's, board's) name or address.
  std::string host = pnh.param<std::string>("host", "");
  if (host.empty())
  {
    host = defaults.host;
  }
  if (host.empty())
  {
    throw MissingParameter(pnh, "host", defaults.host_alternative);
  }
  // ~tcp_port: the control's TCP port.
  const int fallback = defaults.tcp_port != 0 ? defaults.tcp_port : required<int>(pnh, "tcp_port");
  uint16_t port =
      tcpPort(pnh, "tcp_port", fallback, defaults.zero_port_is_default ? PortZero::kMeansAny : PortZero::kRefused);
  if (port == 0)
  {
    port = static_cast<uint16_t>(defaults.tcp_port);
  }
  // ~connect_timeout: s allowed for a TCP connection.
  LinkSettings link = LinkSettings::tcp(host, port, seconds(pnh, "connect_timeout", defaults.connect_timeout));
  // ~wire_trace: a folder; when set, every byte of the connection, both ways, goes to a trace file
  // there (one per connection, at most 16 MiB each).
  pnh.param<std::string>("wire_trace", link.wire_trace.dir, "");
  link.validate();
  return link;
}

LinkSettings link(const ros::NodeHandle& pnh, unsigned default_baud, const TcpLinkDefaults& tcp)
{
  return pnh.hasParam("port") ? serialLink(pnh, default_baud) : tcpLink(pnh, tcp);
}

uint16_t tcpPort(const ros::NodeHandle& pnh, const std::string& name, int fallback, PortZero zero)
{
  int value = fallback;
  pnh.param(name, value, fallback);
  const int lowest = zero == PortZero::kMeansAny ? 0 : 1;
  if (value < lowest || value > 65535)
  {
    throw ConfigError(pnh.resolveName(name) + " must be a TCP port (" + std::to_string(lowest) + "..65535), not " +
                      std::to_string(value));
  }
  return static_cast<uint16_t>(value);
}

std::string choice(const ros::NodeHandle& pnh, const std::string& name, const std::string& fallback,
                   std::initializer_list<const char*> choices)
{
  std::string value = fallback;
  pnh.param(name, value, fallback);
  std::string listed;
  for (const char* each : choices)
  {
    if (value == each)
    {
      return value;
    }
    listed += std::string(listed.empty() ? "" : ", ") + each;
  }
  throw ConfigError(pnh.resolveName(name) + " must be one of " + listed + ", not '" + value + "'");
}

Milliseconds seconds(const ros::NodeHandle& pnh, const std::string& name, double fallback_seconds)
{
  return Milliseconds(static_cast<Milliseconds::rep>(std::llround(positive(pnh, name, fallback_seconds) * 1000.0)));
}
}  // namespace params
}  // namespace cnc_bridge
