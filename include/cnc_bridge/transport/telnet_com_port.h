// Telnet with COM Port Control, the protocol of serial device servers that let the client set up
// the line: RFC 854/855 (Telnet commands and option negotiation), RFC 856 (binary transmission)
// and RFC 2217 (https://www.rfc-editor.org/rfc/rfc2217). Bytes in, bytes out, no I/O: the
// TelnetSerialLine (network_serial_line.h) drives it over a TCP connection.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "cnc_bridge/transport/serial_settings.h"

namespace cnc_bridge
{
namespace rfc2217
{
// Telnet commands (RFC 854).
constexpr uint8_t kIac = 255;
constexpr uint8_t kDont = 254;
constexpr uint8_t kDo = 253;
constexpr uint8_t kWont = 252;
constexpr uint8_t kWill = 251;
constexpr uint8_t kSb = 250;  ///< subnegotiation begins
constexpr uint8_t kSe = 240;  ///< subnegotiation ends

// Telnet options.
constexpr uint8_t kOptionBinary = 0;           ///< RFC 856: 8-bit data, CR not followed by NUL
constexpr uint8_t kOptionEcho = 1;             ///< RFC 857
constexpr uint8_t kOptionSuppressGoAhead = 3;  ///< RFC 858
constexpr uint8_t kOptionComPort = 44;         ///< RFC 2217

/// COM-PORT-OPTION commands, client to server; the server's answer or notice is the same + 100.
enum class Command : uint8_t
{
  kSignature = 0,
  kSetBaudRate = 1,
  kSetDataSize = 2,
  kSetParity = 3,
  kSetStopSize = 4,
  kSetControl = 5,
  kNotifyLineState = 6,
  kNotifyModemState = 7,
  kFlowControlSuspend = 8,
  kFlowControlResume = 9,
  kSetLineStateMask = 10,
  kSetModemStateMask = 11,
  kPurgeData = 12,
};
constexpr uint8_t kServerOffset = 100;

// Values of SET-CONTROL (outbound flow control, which RFC 2217 says covers both directions for
// XON/XOFF and hardware) and of PURGE-DATA.
constexpr uint8_t kControlNoFlow = 1;
constexpr uint8_t kControlXonXoff = 2;
constexpr uint8_t kControlHardware = 3;
constexpr uint8_t kPurgeReceiveBuffer = 1;  ///< what the server received from the line, not yet sent

/// \brief One line setting to ask of the server, as RFC 2217 encodes it.
struct Setting
{
  Command command;
  std::vector<uint8_t> value;
};

/// \brief The settings that set up a line like \p settings: baud rate, data size, parity, stop
/// size and flow control, in that order.
std::vector<Setting> lineSettings(const SerialSettings& settings);
Setting flowControlSetting(FlowControl flow);

/// \brief "baud rate", "data bits", "parity", "stop bits", "flow control", ...
const char* settingName(Command command);
/// \brief The value in words: "115200", "7", "even", "2", "rts/cts", ...
std::string describeValue(Command command, const std::vector<uint8_t>& value);

/// \brief What the server sent other than line data.
struct Event
{
  enum class Kind
  {
    kWill,
    kWont,
    kDo,
    kDont,
    kComPort,  ///< a COM-PORT-OPTION subnegotiation: command (server's, + 100) and value
    kOther,    ///< any other subnegotiation or command (NOP, AYT, ...): nothing to do
  };
  Kind kind = Kind::kOther;
  uint8_t option = 0;   ///< negotiations: the option
  uint8_t command = 0;  ///< kComPort: the server's command number
  std::vector<uint8_t> value;
};

/// \brief Splits what the server sends into line data and Telnet commands. A command cut between
/// two reads is completed by the next; IAC IAC is one data byte 0xFF. Not thread-safe.
class Decoder
{
 public:
  /// Appends the data bytes of \p bytes to \p data and the commands to \p events.
  void feed(const uint8_t* bytes, size_t size, std::vector<uint8_t>& data, std::vector<Event>& events);

 private:
  enum class State
  {
    kData,
    kCommand,                ///< after IAC
    kOption,                 ///< after IAC WILL/WONT/DO/DONT
    kSubnegotiation,         ///< inside IAC SB ... IAC SE
    kSubnegotiationCommand,  ///< IAC inside a subnegotiation
  };
  void endSubnegotiation(std::vector<Event>& events);

  State state_ = State::kData;
  uint8_t verb_ = 0;
  std::vector<uint8_t> sub_;
};

/// \brief The option negotiation of the client side (RFC 1143's rules, reduced to what a device
/// server needs): this side will do binary, suppress-go-ahead and COM-PORT-OPTION, accepts the
/// server's binary, suppress-go-ahead and echo, and refuses everything else, once (no loops).
class Options
{
 public:
  /// \brief What the client sends on connecting.
  std::vector<uint8_t> start();
  /// \brief The reply due to a negotiation the server sent; empty when none is (it answered our
  /// own request, or repeated what is already agreed).
  std::vector<uint8_t> reply(const Event& event);

  /// The server answered our WILL COM-PORT-OPTION with DO.
  bool comPortAccepted() const { return local_[kOptionComPort] == State::kYes; }
  /// The server answered it with DONT.
  bool comPortRefused() const { return refused_com_port_; }
  /// The server refused binary transmission either way: CR would be followed by NUL on the line.
  bool binaryRefused() const { return refused_binary_; }

 private:
  enum class State : uint8_t
  {
    kNo,
    kYes,
    kWantYes,  ///< asked for, no answer yet
  };
  static bool wantLocal(uint8_t option);
  static bool wantRemote(uint8_t option);

  State local_[256] = {};   ///< options this side performs (WILL)
  State remote_[256] = {};  ///< options the server performs (DO)
  bool refused_com_port_ = false;
  bool refused_binary_ = false;
};

/// \brief Line data ready to send: every 0xFF doubled.
void appendEscaped(const uint8_t* data, size_t size, std::vector<uint8_t>& out);
/// \brief IAC SB COM-PORT-OPTION command value IAC SE, with 0xFF in the value doubled.
std::vector<uint8_t> subnegotiation(Command command, const std::vector<uint8_t>& value);
}  // namespace rfc2217
}  // namespace cnc_bridge
