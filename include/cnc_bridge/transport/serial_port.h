// RS-232 serial port in raw mode with every line option the controls need: Haas settings 11 (baud),
// 12 (parity), 13 (stop bits), 37 (data bits) and the flow control of DNC drip-feed.
#pragma once

#include <sys/types.h>

#include <boost/asio/serial_port.hpp>
#include <chrono>
#include <string>

#include "cnc_bridge/transport/asio_stream.h"

namespace cnc_bridge
{
enum class Parity
{
  kNone,
  kEven,
  kOdd
};

enum class FlowControl
{
  kNone,
  kXonXoff,  ///< handled by the kernel (IXON/IXOFF); drip-feed may handle DC1/DC3 itself instead
  kRtsCts
};

/// \brief Bits on the wire per character: start + data + parity + stop.
unsigned bitsPerCharacter(unsigned data_bits, bool parity, unsigned stop_bits);

/// \brief Line settings of a serial port. Defaults: 9600 8N1, no flow control.
struct SerialSettings
{
  std::string device;
  unsigned baud = 9600;
  unsigned data_bits = 8;  ///< 5..8; 7 with even parity is the ISO tape code of older controls
  Parity parity = Parity::kNone;
  unsigned stop_bits = 1;  ///< 1 or 2
  FlowControl flow_control = FlowControl::kNone;

  /// \brief "/dev/ttyUSB0@9600 8N1" for messages.
  std::string describe() const;
  /// \throws ConfigError if a value is out of range.
  void validate() const;
  /// \brief Characters the line carries per second: baud over start, data, parity and stop bits.
  double charactersPerSecond() const;
};

Parity parseParity(const std::string& text);            ///< none|even|odd; \throws ConfigError
FlowControl parseFlowControl(const std::string& text);  ///< none|xonxoff|rtscts; \throws ConfigError
const char* toString(Parity parity);
const char* toString(FlowControl flow);

/// \brief What SerialPort does with the bytes the driver holds when the port is opened.
enum class InputOnOpen
{
  kDiscard,  ///< drop them: a poller's stale replies belong to no query of this port
  kKeep,     ///< keep them: a control's request sent before the open (an XModem receiver's NAK or
             ///< 'C', a DC3, the start of a punch) is meant for whoever opens the port next
};

/// \brief A serial port (or pty slave) opened raw. Thread-safe only for interrupt().
class SerialPort : public AsioStreamTransport<boost::asio::serial_port>
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
  const SerialSettings& settings() const { return settings_; }
  /// \brief Sets the line settings on the device again: another program that shares the line (a
  /// DNC transfer between two status polls) may have changed them, and they belong to the device,
  /// not to this open port. \throws LinkError.
  void applySettings();

  /// \brief Native file descriptor, for ioctls the interface does not cover (modem lines).
  int nativeHandle() { return stream_.native_handle(); }

 private:
  SerialSettings settings_;
  dev_t device_number_ = 0;  ///< of the device opened
  std::chrono::steady_clock::time_point next_device_check_;
};
}  // namespace cnc_bridge
