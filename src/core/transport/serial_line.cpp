// openSerialLine(): the one place that turns a serial `port` value into a line.
#include "cnc_bridge/transport/serial_line.h"

#include <cctype>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/network_serial_line.h"
#include "cnc_bridge/transport/serial_port.h"

namespace cnc_bridge
{
namespace
{
constexpr const char* kRawScheme = "tcp://";
constexpr const char* kRfc2217Scheme = "rfc2217://";

bool startsWith(const std::string& text, const std::string& prefix)
{
  return text.compare(0, prefix.size(), prefix) == 0;
}

uint16_t parsePortNumber(const std::string& url, const std::string& digits)
{
  const bool all_digits =
      !digits.empty() && digits.size() <= 5 && digits.find_first_not_of("0123456789") == std::string::npos;
  const unsigned long number = all_digits ? std::stoul(digits) : 0;
  if (number < 1 || number > 65535)
  {
    throw ConfigError("serial port '" + url + "': the TCP port must be a number 1..65535, not '" + digits + "'");
  }
  return static_cast<uint16_t>(number);
}

/// host:port or [v6-address]:port, nothing else (no user, no path).
SerialAddress parseNetworkAddress(const std::string& url, const std::string& rest)
{
  SerialAddress address;
  if (rest.find_first_of("/@?#") != std::string::npos)
  {
    throw ConfigError("serial port '" + url + "': give host:port only (no user, path or query)");
  }
  size_t colon = 0;
  if (!rest.empty() && rest.front() == '[')
  {
    const size_t close = rest.find(']');
    if (close == std::string::npos || close + 1 >= rest.size() || rest[close + 1] != ':')
    {
      throw ConfigError("serial port '" + url + "': an IPv6 address is written [address]:port");
    }
    address.host = rest.substr(1, close - 1);
    colon = close + 1;
  }
  else
  {
    colon = rest.rfind(':');
    if (colon == std::string::npos || rest.find(':') != colon)
    {
      throw ConfigError("serial port '" + url + "': no port: write host:port (the device server's TCP port)");
    }
    address.host = rest.substr(0, colon);
  }
  if (address.host.empty())
  {
    throw ConfigError("serial port '" + url + "': no host");
  }
  address.port = parsePortNumber(url, rest.substr(colon + 1));
  return address;
}
}  // namespace

SerialAddress parseSerialAddress(const std::string& port)
{
  SerialAddress address;
  if (startsWith(port, kRawScheme))
  {
    address = parseNetworkAddress(port, port.substr(std::char_traits<char>::length(kRawScheme)));
    address.kind = SerialAddress::Kind::kRawTcp;
  }
  else if (startsWith(port, kRfc2217Scheme))
  {
    address = parseNetworkAddress(port, port.substr(std::char_traits<char>::length(kRfc2217Scheme)));
    address.kind = SerialAddress::Kind::kRfc2217;
  }
  else if (port.find("://") != std::string::npos)
  {
    throw ConfigError("serial port '" + port +
                      "': unknown kind of link; a serial port is a device path, tcp://host:port (a device "
                      "server's raw TCP port) or rfc2217://host:port (Telnet COM Port Control)");
  }
  else
  {
    address.device = port;
  }
  return address;
}

namespace
{
std::unique_ptr<SerialLine> openUntraced(const SerialSettings& settings, InputOnOpen on_open,
                                         Milliseconds connect_timeout)
{
  const SerialAddress address = parseSerialAddress(settings.device);
  switch (address.kind)
  {
    case SerialAddress::Kind::kDevice:
      return std::make_unique<SerialPort>(settings, on_open);
    case SerialAddress::Kind::kRawTcp:
      return RawTcpSerialLine::open(settings, address, on_open, connect_timeout);
    case SerialAddress::Kind::kRfc2217:
      return TelnetSerialLine::open(settings, address, on_open, connect_timeout);
  }
  throw ConfigError("serial port '" + settings.device + "': unknown kind of link");
}
}  // namespace

std::unique_ptr<SerialLine> openSerialLine(const SerialSettings& settings, InputOnOpen on_open,
                                           Milliseconds connect_timeout)
{
  settings.validate();
  return traced<SerialLine, TracingSerialLine>(openUntraced(settings, on_open, connect_timeout), settings.wire_trace,
                                               settings.device);
}
}  // namespace cnc_bridge
