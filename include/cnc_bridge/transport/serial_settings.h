// The line settings of a serial port: Haas settings 11 (baud), 12 (parity), 13 (stop bits), 37
// (data bits) and the flow control of DNC drip-feed. The same settings set up a local port and a
// device server's port over RFC 2217 (serial_line.h).
#pragma once

#include <string>

#include "cnc_bridge/transport/wire_trace.h"

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
  /// Off unless set: every byte of the line, both ways, into a trace file (wire_trace.h).
  WireTraceSettings wire_trace;

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
}  // namespace cnc_bridge
