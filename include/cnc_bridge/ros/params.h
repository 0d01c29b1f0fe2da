// Parameter helpers shared by the nodes: required parameters fail with the resolved name, ranges
// are checked, and the link parameters have the same names in every node (docs/ROS_INTERFACE.md).
#pragma once

#include <ros/ros.h>

#include <initializer_list>
#include <string>
#include <type_traits>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/common/soft_limits.h"
#include "cnc_bridge/transport/link_factory.h"
#include "cnc_bridge/transport/serial_port.h"

namespace cnc_bridge
{
namespace params
{
/// \brief A required parameter that was not given (or given empty): "Required parameter
/// /ns/node/name not given". runNode() adds the launch-file argument that sets it (each node's
/// launch file passes the parameter as the argument of the same name).
class MissingParameter : public ConfigError
{
 public:
  /// \param alternative what else would have done, e.g. "nor INET_ADD in ~settings_file"
  MissingParameter(const ros::NodeHandle& pnh, const std::string& name, const std::string& alternative = "");
  /// The parameter's private name (and so the launch argument's), e.g. "port".
  const std::string& parameter() const { return parameter_; }

 private:
  std::string parameter_;
};

/// \brief Reads a required parameter; an empty string counts as not given.
/// \throws MissingParameter naming the parameter's resolved name.
template <class T>
T required(const ros::NodeHandle& pnh, const std::string& name)
{
  T value;
  bool given = pnh.getParam(name, value);
  if constexpr (std::is_same_v<T, std::string>)
  {
    given = given && !value.empty();
  }
  if (!given)
  {
    throw MissingParameter(pnh, name);
  }
  return value;
}

/// \brief Reads a positive number; logs and falls back to \p fallback if the value is not positive.
double positive(const ros::NodeHandle& pnh, const std::string& name, double fallback);

/// \brief ~port (required: a device path, tcp://host:port or rfc2217://host:port), ~baud,
/// ~data_bits, ~parity, ~stop_bits, ~flow_control.
/// \throws ConfigError naming the parameter on a missing port or an invalid value.
SerialSettings serialSettings(const ros::NodeHandle& pnh, unsigned default_baud = 9600);

/// \brief Defaults of a node's TCP link parameters (~host, ~tcp_port, ~connect_timeout).
struct TcpLinkDefaults
{
  std::string host;                   ///< when ~host is not set or empty; empty: ~host is required
  std::string host_alternative;       ///< what else would have given a host, for the missing-~host error
  int tcp_port = 0;                   ///< when ~tcp_port is not set; 0: ~tcp_port is required
  bool zero_port_is_default = false;  ///< ~tcp_port: 0 also means the default above
  double connect_timeout = 3.0;       ///< s
};

/// \brief A serial link: serialSettings() (~port, ~baud, ~data_bits, ~parity, ~stop_bits,
/// ~flow_control). The device server's connect timeout is openSerialLine()'s (5 s).
/// \throws ConfigError naming the parameter.
LinkSettings serialLink(const ros::NodeHandle& pnh, unsigned default_baud = 9600,
                        InputOnOpen on_open = InputOnOpen::kDiscard);

/// \brief A TCP link: ~host, ~tcp_port (1..65535), ~connect_timeout (s).
/// \throws ConfigError (MissingParameter) naming the parameter.
LinkSettings tcpLink(const ros::NodeHandle& pnh, const TcpLinkDefaults& defaults);

/// \brief A serial link when ~port is given (serialLink()), else a TCP link (tcpLink()): a control
/// reached either on its RS-232 port or over the network.
LinkSettings link(const ros::NodeHandle& pnh, unsigned default_baud, const TcpLinkDefaults& tcp);

/// What port 0 means for a TCP port parameter.
enum class PortZero
{
  kRefused,   ///< 0 is not a port: 1..65535
  kMeansAny,  ///< 0 asks for any free port (a server) or for a default found elsewhere
};

/// \brief A TCP port parameter (~tcp_port, ~listen_port, ...), \p fallback when not set.
/// \throws ConfigError naming the parameter, the range and the value given.
uint16_t tcpPort(const ros::NodeHandle& pnh, const std::string& name, int fallback, PortZero zero = PortZero::kRefused);

/// \brief A string parameter that must be one of \p choices (\p fallback when not set).
/// \throws ConfigError naming the parameter, the choices and the value given.
std::string choice(const ros::NodeHandle& pnh, const std::string& name, const std::string& fallback,
                   std::initializer_list<const char*> choices);

/// \brief ~soft_limits: `{x: [min, max], y: [min, max], z: [min, max]}` in metres, any axis may be
/// left out (no limit on it); not set: no soft limits.
/// \throws ConfigError naming the parameter if it is not such a dictionary, a bound is not a finite
/// number or min is above max.
SoftLimits softLimits(const ros::NodeHandle& pnh, const std::string& name = "soft_limits");

/// \brief Milliseconds from a parameter given in seconds (float), e.g. ~timeout: 1.5.
Milliseconds seconds(const ros::NodeHandle& pnh, const std::string& name, double fallback_seconds);
}  // namespace params

/// \brief Routes the core's log lines to rosconsole under the node's name.
void routeCoreLogToRosconsole();
}  // namespace cnc_bridge
