// A serial line at a device server on the network (serial_line.h says which `port` values lead
// here). Both kinds keep TCP keepalive probes going, so a cable pulled on the network side or a
// server switched off fails the line within seconds (kDeadPeerWithin) instead of leaving a node
// waiting on a connection that no longer exists; a server that closes the connection (restarted,
// or giving its port to one client at a time while another holds it) fails it at once, with what
// the server said.
#pragma once

#include <chrono>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "cnc_bridge/transport/serial_line.h"
#include "cnc_bridge/transport/tcp.h"
#include "cnc_bridge/transport/telnet_com_port.h"

namespace cnc_bridge
{
/// How long an unanswered peer (keepalive probes while idle, unacknowledged data while sending)
/// may take before the line fails.
constexpr std::chrono::seconds kDeadPeerWithin{10};
/// How long a new raw TCP connection is watched for a server that turns it away (another client
/// holds the port) before the line counts as open.
constexpr std::chrono::milliseconds kTurnedAwayWithin{150};
/// A server that turns a new connection away is asked again for this long (every
/// kBusyRetryEvery), within the connect timeout: it may still be closing the previous connection
/// (ser2net drains its port first), and a node that closes a line and reopens it must not fail.
constexpr std::chrono::milliseconds kBusyRetryFor{2000};
constexpr std::chrono::milliseconds kBusyRetryEvery{50};

/// \brief What both kinds of device-server line share: the TCP connection, the settings asked
/// for, and the calls that go straight to the connection. Thread-safe only for interrupt().
class NetworkSerialLine : public SerialLine
{
 public:
  /// \brief Waits until the server has acknowledged every byte written (what it still holds for
  /// its own port is out of sight).
  void drain() override;
  /// \returns bytes written that the server has not acknowledged yet.
  size_t pendingOutput() const override;
  void interrupt() override;
  void close() override;
  bool isOpen() const override;
  const SerialSettings& settings() const override { return settings_; }

 protected:
  NetworkSerialLine(SerialSettings settings, std::unique_ptr<TcpConnection> connection);
  /// \throws LinkError with \p error and what a closed or silent server means.
  [[noreturn]] void fail(const LinkError& error) const;

  SerialSettings settings_;
  std::unique_ptr<TcpConnection> connection_;
};

/// \brief A device server's raw TCP port: the bytes are the line's, the line settings are the
/// server's own (settings() only tells this side the baud rate its waits are measured in).
/// Thread-safe only for interrupt().
class RawTcpSerialLine : public NetworkSerialLine
{
 public:
  static std::unique_ptr<RawTcpSerialLine> open(const SerialSettings& settings, const SerialAddress& address,
                                                InputOnOpen on_open, Milliseconds connect_timeout);

  using Transport::write;
  size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override;
  void write(const uint8_t* data, size_t size, Milliseconds timeout) override;
  void discardInput() override;
  std::string describe() const override;

  /// Nothing to send: the server keeps its own line settings.
  void applySettings() override {}
  /// Nothing to send: the server keeps its own flow control.
  void setFlowControl(FlowControl /*flow*/) override {}

 private:
  RawTcpSerialLine(SerialSettings settings, std::unique_ptr<TcpConnection> connection);
  /// \throws LinkError when the server closes the new connection at once, with what it said.
  void refuseIfTurnedAway();

  std::vector<uint8_t> held_;  ///< line data that arrived while refuseIfTurnedAway() watched
  size_t held_start_ = 0;
};

/// \brief A device server's port over Telnet with COM Port Control (RFC 2217): the line is set up
/// from settings() and every setting is checked against the server's answer; data bytes 0xFF
/// (Telnet's IAC) are escaped both ways, so binary XModem blocks pass intact; the server's
/// flow-control suspend and resume hold this side's writes. Thread-safe only for interrupt().
class TelnetSerialLine : public NetworkSerialLine
{
 public:
  /// \throws LinkError when the server does not speak RFC 2217 on that port or refuses a setting.
  static std::unique_ptr<TelnetSerialLine> open(const SerialSettings& settings, const SerialAddress& address,
                                                InputOnOpen on_open, Milliseconds connect_timeout);

  using Transport::write;
  size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override;
  void write(const uint8_t* data, size_t size, Milliseconds timeout) override;
  /// \brief Drops what this side holds and asks the server to purge its receive buffer.
  void discardInput() override;
  std::string describe() const override;

  void applySettings() override;
  void setFlowControl(FlowControl flow) override;

  /// \brief What the server last reported for each setting ("baud rate 9600", ...), for diagnostics
  /// and the doctor; empty before the line was set up.
  std::vector<std::string> serverSettings() const;

 private:
  TelnetSerialLine(SerialSettings settings, std::unique_ptr<TcpConnection> connection, Milliseconds answer_timeout);
  /// Negotiates the options and sets the line up; \throws LinkError naming what the server said
  /// when it closes the connection meanwhile.
  void setUp();
  void negotiate();
  /// Sends every setting at once, then waits for each answer and checks it.
  void request(const std::vector<rfc2217::Setting>& settings);
  /// Reads from the connection for up to \p timeout, handles every Telnet command, keeps the data.
  /// \returns false when nothing arrived in time.
  bool pump(Milliseconds timeout);
  void handle(const rfc2217::Event& event);
  static Milliseconds left(std::chrono::steady_clock::time_point deadline);
  void send(const std::vector<uint8_t>& bytes, Milliseconds timeout);

  Milliseconds answer_timeout_;
  rfc2217::Decoder decoder_;
  rfc2217::Options options_;
  std::vector<uint8_t> data_;  ///< line data received and not read yet
  size_t data_start_ = 0;      ///< first unread byte of data_
  bool suspended_ = false;     ///< the server asked us to stop sending (FLOWCONTROL-SUSPEND)
  std::map<rfc2217::Command, std::vector<uint8_t>> answers_;  ///< the server's latest answer to each setting
};
}  // namespace cnc_bridge
