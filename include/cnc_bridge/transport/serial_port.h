// A local RS-232 port (or a pty) in raw mode with every line option the controls need
// (serial_settings.h). Nodes open it through openSerialLine(), which also reaches device servers.
#pragma once

#include <sys/types.h>

#include <boost/asio/serial_port.hpp>
#include <chrono>
#include <string>

#include "cnc_bridge/transport/asio_stream.h"
#include "cnc_bridge/transport/serial_line.h"
#include "cnc_bridge/transport/serial_settings.h"

namespace cnc_bridge
{
/// \brief A serial port (or pty slave) opened raw. Thread-safe only for interrupt().
class SerialPort : public AsioStreamTransport<boost::asio::serial_port, SerialLine>
{
 public:
  /// \brief Opens and configures the port.
  /// \throws ConfigError for invalid settings, LinkError if the device cannot be opened.
  explicit SerialPort(SerialSettings settings, InputOnOpen on_open = InputOnOpen::kDiscard);
  ~SerialPort() override;

  /// \brief Reads as every transport does; about twice a second it also checks that the
  /// configured path still names the open device. \throws LinkError when it does not.
  size_t read(uint8_t* buffer, size_t size, Milliseconds timeout) override;
  using Transport::write;
  /// \brief Writes as every transport does, but first straight into the driver's buffer, where a
  /// packet or a reply nearly always fits: one system call instead of a trip through the reactor.
  void write(const uint8_t* data, size_t size, Milliseconds timeout) override;
  /// \returns true when settings().device now names another device than the open one, or none:
  /// a USB adapter re-plugged and given another ttyUSB behind the same /dev/serial/by-id link, a
  /// simulator restarted on a new pty. The open port then leads nowhere, or to someone else's pty.
  bool deviceReplaced() const;
  void drain() override;
  size_t pendingOutput() const override;
  void discardInput() override;
  std::string describe() const override { return settings_.describe(); }
  const SerialSettings& settings() const override { return settings_; }
  /// \brief Sets the line settings on the device again (termios). \throws LinkError.
  void applySettings() override;
  /// \brief XON/XOFF in the kernel (IXON/IXOFF), RTS/CTS (CRTSCTS) or none. \throws LinkError.
  void setFlowControl(FlowControl flow) override;

  /// \brief Native file descriptor, for ioctls the interface does not cover (modem lines).
  int nativeHandle() { return stream_.native_handle(); }

 private:
  void configure(FlowControl flow);

  SerialSettings settings_;
  dev_t device_number_ = 0;  ///< of the device opened
  std::chrono::steady_clock::time_point next_device_check_;
};
}  // namespace cnc_bridge
