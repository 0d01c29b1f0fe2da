// A serial line wherever its port is. Most shops hang the RS-232 port of an older control on a
// serial device server (Moxa NPort, Lantronix, Digi, a computer running ser2net) rather than wire
// it to the cell computer, so a serial `port` is one of:
//   /dev/ttyUSB0, /dev/serial/by-id/...  a local device (or a pty): SerialPort
//   tcp://host:port                      a device server's raw TCP port; the line (baud, parity,
//                                        flow control) is set up on the server
//   rfc2217://host:port                  a device server speaking Telnet with COM Port Control
//                                        (RFC 2217, https://www.rfc-editor.org/rfc/rfc2217): the
//                                        line is set up from here, from the same settings as a
//                                        local port, and the server's answers are checked
// Every serial node and the command line open their line with openSerialLine() and never ask which
// kind they have.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

#include "cnc_bridge/transport/serial_settings.h"
#include "cnc_bridge/transport/transport.h"

namespace cnc_bridge
{
/// \brief What SerialPort does with the bytes the driver holds when the port is opened.
enum class InputOnOpen
{
  kDiscard,  ///< drop them: a poller's stale replies belong to no query of this port
  kKeep,     ///< keep them: a control's request sent before the open (an XModem receiver's NAK or
             ///< 'C', a DC3, the start of a punch) is meant for whoever opens the port next
};

/// \brief A Transport that is a serial line: it knows its line settings and can set them again.
class SerialLine : public Transport
{
 public:
  /// \brief The settings asked for; settings().device is the path or URL the line was opened with.
  virtual const SerialSettings& settings() const = 0;

  /// \brief Sets the line settings on the port again: another program that shares the line (a DNC
  /// transfer between two status polls) may have changed them, and they belong to the port, not to
  /// this connection. A device server on raw TCP keeps its own settings: nothing is sent.
  /// \throws LinkError when the port (or the server) refuses a setting, naming it.
  virtual void applySettings() = 0;

  /// \brief Switches the line's flow control until applySettings() restores the configured one:
  /// the drip-feed reads DC1/DC3 itself, so it needs none below it, or RTS/CTS in the driver or on
  /// the server. A raw TCP line cannot change it (the server's setting stays). \throws LinkError.
  virtual void setFlowControl(FlowControl flow) = 0;
};

/// \brief A serial line traced into a wire trace (wire_trace.h): the line it wraps, unchanged.
class TracingSerialLine : public TracingLink<SerialLine>
{
 public:
  using TracingLink<SerialLine>::TracingLink;
  const SerialSettings& settings() const override { return inner().settings(); }
  void applySettings() override { inner().applySettings(); }
  void setFlowControl(FlowControl flow) override { inner().setFlowControl(flow); }
};

/// \brief The parts of a serial `port` value.
struct SerialAddress
{
  enum class Kind
  {
    kDevice,   ///< a path: /dev/ttyUSB0
    kRawTcp,   ///< tcp://host:port
    kRfc2217,  ///< rfc2217://host:port
  };
  Kind kind = Kind::kDevice;
  std::string device;  ///< kDevice: the path
  std::string host;    ///< network kinds: name or address (an IPv6 address in brackets in the URL)
  uint16_t port = 0;   ///< network kinds: 1..65535

  bool networked() const { return kind != Kind::kDevice; }
};

/// \brief Reads a serial `port` value: a device path, `tcp://host:port` or `rfc2217://host:port`.
/// \throws ConfigError naming what is wrong (an unknown scheme, no port, a port out of range, a path
/// or a user in the URL).
SerialAddress parseSerialAddress(const std::string& port);

/// \brief Opens the serial line \p settings.device names, configured from \p settings, and traced
/// when settings.wire_trace says so.
/// \param connect_timeout for the network kinds: the TCP connect and, for RFC 2217, the server's
///        answers to the line settings.
/// \throws ConfigError for invalid settings, LinkError when the line cannot be opened or set up
///         (the message says what to check: the device, the server's port mode, another client).
std::unique_ptr<SerialLine> openSerialLine(const SerialSettings& settings, InputOnOpen on_open = InputOnOpen::kDiscard,
                                           Milliseconds connect_timeout = Milliseconds(5000));
}  // namespace cnc_bridge
