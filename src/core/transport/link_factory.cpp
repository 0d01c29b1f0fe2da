// The link factory (link_factory.h): settings -> an opener, a hardware id and a port-lock name.
#include "cnc_bridge/transport/link_factory.h"

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/tcp.h"

namespace cnc_bridge
{
LinkSettings LinkSettings::serialLine(SerialSettings serial, InputOnOpen on_open)
{
  LinkSettings settings;
  settings.kind = Kind::kSerial;
  settings.serial = std::move(serial);
  settings.input_on_open = on_open;
  return settings;
}

LinkSettings LinkSettings::tcp(std::string host, uint16_t port, Milliseconds connect_timeout)
{
  LinkSettings settings;
  settings.kind = Kind::kTcp;
  settings.host = std::move(host);
  settings.tcp_port = port;
  settings.connect_timeout = connect_timeout;
  return settings;
}

bool LinkSettings::networked() const
{
  return !isSerial() || parseSerialAddress(serial.device).networked();
}

void LinkSettings::validate() const
{
  if (connect_timeout <= Milliseconds(0))
  {
    throw ConfigError(hardwareId() + ": the connect timeout must be positive");
  }
  if (isSerial())
  {
    serial.validate();
    parseSerialAddress(serial.device);  // a device path or a device server's address
    return;
  }
  if (host.empty())
  {
    throw ConfigError("TCP link: no host given");
  }
  if (tcp_port == 0)
  {
    throw ConfigError("TCP link to " + host + ": the port must be 1..65535, not 0");
  }
}

std::string LinkSettings::hardwareId() const
{
  return isSerial() ? serial.describe() : host + ":" + std::to_string(tcp_port);
}

std::string LinkSettings::lockDevice() const
{
  return isSerial() ? serial.device : std::string();
}

std::unique_ptr<Transport> openLink(const LinkSettings& settings)
{
  if (settings.isSerial())
  {
    return openSerialLine(settings.serial, settings.input_on_open, settings.connect_timeout);
  }
  settings.validate();
  return traced<Transport>(TcpConnection::connect(settings.host, settings.tcp_port, settings.connect_timeout),
                           settings.wire_trace, settings.hardwareId());
}

LinkFactory linkFactory(LinkSettings settings)
{
  settings.validate();
  return [settings = std::move(settings)] { return openLink(settings); };
}
}  // namespace cnc_bridge
