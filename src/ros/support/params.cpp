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

SerialSettings serialSettings(const ros::NodeHandle& pnh, unsigned default_baud)
{
  SerialSettings settings;
  // ~port: serial device, e.g. /dev/ttyUSB0.
  settings.device = required<std::string>(pnh, "port");
  int baud = static_cast<int>(default_baud), data_bits = 8, stop_bits = 1;
  std::string parity = "none", flow = "none";
  // ~baud: bits per second (Haas setting 11).
  pnh.param("baud", baud, baud);
  // ~data_bits: 7 or 8 (Haas setting 37).
  pnh.param("data_bits", data_bits, data_bits);
  // ~parity: none, even or odd (Haas setting 12).
  pnh.param("parity", parity, parity);
  // ~stop_bits: 1 or 2 (Haas setting 13).
  pnh.param("stop_bits", stop_bits, stop_bits);
  // ~flow_control: none, xonxoff or rtscts.
  pnh.param("flow_control", flow, flow);
  if (baud <= 0 || data_bits <= 0 || stop_bits <= 0)
  {
    throw ConfigError(pnh.resolveName("baud") + ", data_bits and stop_bits must be positive");
  }
  settings.baud = static_cast<unsigned>(baud);
  settings.data_bits = static_cast<unsigned>(data_bits);
  settings.stop_bits = static_cast<unsigned>(stop_bits);
  settings.parity = parseParity(parity);
  settings.flow_control = parseFlowControl(flow);
  // ~wire_trace: a folder; when set, every byte of the line, both ways, goes to a trace file there
  // (one per opening of the line, at most 16 MiB each; `cnc_dnc replay` plays one back).
  pnh.param<std::string>("wire_trace", settings.wire_trace.dir, "");
  settings.validate();
  return settings;
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
