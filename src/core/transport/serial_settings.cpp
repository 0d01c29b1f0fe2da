// SerialSettings: validation, parsing and the text of line settings, for every kind of serial line.
#include "cnc_bridge/transport/serial_settings.h"

#include <sstream>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
std::string SerialSettings::describe() const
{
  std::ostringstream out;
  out << device << "@" << baud << " " << data_bits
      << (parity == Parity::kNone   ? 'N'
          : parity == Parity::kEven ? 'E'
                                    : 'O')
      << stop_bits;
  if (flow_control != FlowControl::kNone)
  {
    out << " " << toString(flow_control);
  }
  return out.str();
}

unsigned bitsPerCharacter(unsigned data_bits, bool parity, unsigned stop_bits)
{
  return 1 + data_bits + (parity ? 1 : 0) + stop_bits;
}

double SerialSettings::charactersPerSecond() const
{
  return static_cast<double>(baud) / bitsPerCharacter(data_bits, parity != Parity::kNone, stop_bits);
}

void SerialSettings::validate() const
{
  if (device.empty())
  {
    throw ConfigError("serial port: no device given");
  }
  if (baud == 0)
  {
    throw ConfigError(device + ": baud rate must be positive");
  }
  if (data_bits < 5 || data_bits > 8)
  {
    throw ConfigError(device + ": data bits must be 5..8, not " + std::to_string(data_bits));
  }
  if (stop_bits != 1 && stop_bits != 2)
  {
    throw ConfigError(device + ": stop bits must be 1 or 2, not " + std::to_string(stop_bits));
  }
}

Parity parseParity(const std::string& text)
{
  if (text == "none" || text == "N" || text == "n")
    return Parity::kNone;
  if (text == "even" || text == "E" || text == "e")
    return Parity::kEven;
  if (text == "odd" || text == "O" || text == "o")
    return Parity::kOdd;
  throw ConfigError("parity must be none, even or odd, not '" + text + "'");
}

FlowControl parseFlowControl(const std::string& text)
{
  if (text == "none")
    return FlowControl::kNone;
  if (text == "xonxoff" || text == "software")
    return FlowControl::kXonXoff;
  if (text == "rtscts" || text == "hardware")
    return FlowControl::kRtsCts;
  throw ConfigError("flow control must be none, xonxoff or rtscts, not '" + text + "'");
}

const char* toString(Parity parity)
{
  switch (parity)
  {
    case Parity::kNone:
      return "none";
    case Parity::kEven:
      return "even";
    case Parity::kOdd:
      return "odd";
  }
  return "?";
}

const char* toString(FlowControl flow)
{
  switch (flow)
  {
    case FlowControl::kNone:
      return "none";
    case FlowControl::kXonXoff:
      return "xonxoff";
    case FlowControl::kRtsCts:
      return "rtscts";
  }
  return "?";
}
}  // namespace cnc_bridge
