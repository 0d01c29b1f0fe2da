// The one link factory: what a node's link parameters say (a serial line, wherever its port is, or
// a TCP connection to a network control) -> a function that opens the link, the name diagnostics
// give the device and the name of the port lock a shared line is guarded by. Every node builds its
// link from a LinkSettings (read by params::link and its kin in the ROS layer) and never asks which
// kind it has. ROS-free.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "cnc_bridge/transport/serial_line.h"
#include "cnc_bridge/transport/serial_settings.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
/// \brief Where a node's link goes and how it is opened.
struct LinkSettings
{
  enum class Kind
  {
    kSerial,  ///< a serial line: serial.device is a path, tcp://host:port or rfc2217://host:port
    kTcp,     ///< a TCP connection to host:tcp_port (a network control, an agent, a board)
  };
  Kind kind = Kind::kSerial;

  SerialSettings serial;                              ///< kSerial: the device and the line settings
  InputOnOpen input_on_open = InputOnOpen::kDiscard;  ///< kSerial: what the port keeps when opened

  std::string host;       ///< kTcp: name or address
  uint16_t tcp_port = 0;  ///< kTcp: 1..65535

  /// kTcp: where the connection's bytes are traced (off unless set; a serial line's own trace is
  /// serial.wire_trace).
  WireTraceSettings wire_trace;

  /// The TCP connect of a kTcp link, and of a serial line at a device server (with, for RFC 2217,
  /// the server's answers to the line settings). 5 s: openSerialLine()'s own default.
  Milliseconds connect_timeout{5000};

  /// \brief A serial line on \p serial.device.
  static LinkSettings serialLine(SerialSettings serial, InputOnOpen on_open = InputOnOpen::kDiscard);
  /// \brief A TCP connection to \p host:\p port.
  static LinkSettings tcp(std::string host, uint16_t port, Milliseconds connect_timeout);

  bool isSerial() const { return kind == Kind::kSerial; }
  /// \brief The link crosses a network: a TCP link, or a serial line at a device server.
  bool networked() const;

  /// \throws ConfigError naming what is wrong: invalid line settings, a serial port value that is
  /// neither a path nor a device server's address, no host, port 0, a timeout that is not positive.
  void validate() const;

  /// \brief What diagnostics and log lines call the device: "/dev/ttyUSB0@9600 8N1" (the line and its
  /// settings), "10.0.0.5:6666" (host:port).
  std::string hardwareId() const;

  /// \brief The name a PortLock takes for this link (PortLock(lockDevice(), dir)): the serial device
  /// or device server address, whose lock every program on that line shares; empty for a TCP link,
  /// which has no line to share.
  std::string lockDevice() const;
};

/// Opens the link; throws (LinkError, ConfigError) when it cannot. What ReconnectingLink::Opener,
/// a dprnt::StreamInput or an HTTP client's connector is given.
using LinkFactory = std::function<std::unique_ptr<Transport>()>;

/// \brief Opens the link \p settings describe: openSerialLine() or TcpConnection::connect().
/// \throws ConfigError for invalid settings, LinkError when the link cannot be opened.
std::unique_ptr<Transport> openLink(const LinkSettings& settings);

/// \brief A factory opening \p settings' link on each call. The settings are checked here, once,
/// so that a wrong parameter stops the node at start instead of failing every reconnection.
/// \throws ConfigError as LinkSettings::validate().
LinkFactory linkFactory(LinkSettings settings);
}  // namespace cnc_bridge
