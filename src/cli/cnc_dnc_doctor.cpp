// cnc_dnc doctor: commissioning a serial link (the table in cnc_dnc.cpp lists it).
//
//   cnc_dnc doctor --port DEV [--baud B] [--parity P] [--data-bits N] [--stop-bits N] [--listen S]
//
// Says whether the port opens and, if not, why in words (missing device, permission, busy); which
// settings it applied; which other processes have the port open; and with --listen S, what the
// control sends in S seconds (press PUNCH or SEND, or start a DPRNT program): bytes, framing
// errors, the data bits and parity the bytes show, whether the baud rate looks right, and the
// control profiles of config/controls/ that match; a peer whose bytes say what it waits for (an
// XModem receiver's NAK or 'C', a control's DC1 asking for a drip-feed) is named, the line judged
// good. Exit status 0 when the port opens and no other process has it open (and, with --listen,
// something was received), 1 otherwise, 2 for a bad command line.
//
// A device server's port (--port tcp://host:port or rfc2217://host:port) is checked along its
// network path: the TCP connection, the Telnet negotiation (RFC 2217), the line settings the server
// reports having set, and whether the server keeps the connection (one that serves its port to one
// client at a time says so and closes it while another client holds the port). A failure says in
// words what to check: the address and a firewall, the server's port mode (raw TCP or RFC 2217),
// another client.
#include <termios.h>
#include <unistd.h>

#include <boost/program_options.hpp>
#include <chrono>
#include <iostream>
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/network_serial_line.h"
#include "cnc_bridge/transport/port_doctor.h"
#include "cnc_bridge/transport/serial_port.h"
#include "serial_options.h"

namespace po = boost::program_options;

namespace cnc_bridge
{
namespace cli
{
namespace
{
/// Framing and parity errors as the driver marks them with PARMRK: \377 \0 X for a character
/// received in error, \377 \377 for a real \377. Removes the marks; \returns the errors.
size_t takeErrorMarks(std::vector<uint8_t>& bytes)
{
  std::vector<uint8_t> clean;
  size_t errors = 0;
  for (size_t i = 0; i < bytes.size(); ++i)
  {
    if (bytes[i] == 0xff && i + 1 < bytes.size() && bytes[i + 1] == 0xff)
    {
      clean.push_back(0xff);
      ++i;
    }
    else if (bytes[i] == 0xff && i + 2 < bytes.size() && bytes[i + 1] == 0x00)
    {
      ++errors;
      i += 2;
    }
    else
    {
      clean.push_back(bytes[i]);
    }
  }
  bytes.swap(clean);
  return errors;
}

/// Reads what arrives for \p seconds at 8 data bits without parity, so a parity bit shows as bit 7,
/// with framing errors marked by the driver (a local port; a device server does not report them).
LineGuess listen(const SerialSettings& asked, double seconds)
{
  SerialSettings raw = asked;
  raw.data_bits = 8;
  raw.parity = Parity::kNone;
  raw.flow_control = FlowControl::kNone;
  const auto line = openSerialLine(raw, InputOnOpen::kKeep);
  SerialLine& port = *line;
  if (auto* local = dynamic_cast<SerialPort*>(line.get()))
  {
    struct termios tio;
    if (::tcgetattr(local->nativeHandle(), &tio) == 0)
    {
      tio.c_iflag = (tio.c_iflag | PARMRK) & ~(IGNPAR | ISTRIP);
      ::tcsetattr(local->nativeHandle(), TCSANOW, &tio);
    }
  }
  std::vector<uint8_t> bytes;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  uint8_t buffer[4096];
  try
  {
    for (auto now = std::chrono::steady_clock::now(); now < deadline; now = std::chrono::steady_clock::now())
    {
      const auto left = std::chrono::duration_cast<Milliseconds>(deadline - now);
      const size_t n = port.read(buffer, sizeof(buffer), std::max(left, Milliseconds(1)));
      bytes.insert(bytes.end(), buffer, buffer + n);
    }
  }
  catch (const LinkError& e)
  {
    // The line went away (an adapter unplugged, a simulated control ended): judge what came.
    std::cout << "listen: stopped early: " << e.what() << "\n";
  }
  const size_t errors = dynamic_cast<SerialPort*>(line.get()) ? takeErrorMarks(bytes) : 0;
  return guessLineSettings(bytes, errors, asked.baud);
}

void printGuess(const LineGuess& guess, double seconds)
{
  if (guess.bytes == 0 && guess.framing_errors == 0)
  {
    // Not kNoAnswerHint: its advice is to run this very command.
    std::cout << "listen: nothing received in " << seconds
              << " s: the control sends only while the doctor listens, so start the doctor first and then press "
                 "PUNCH/SEND on the control (or start its DPRNT program, or put it in RECV for XModem) within the "
                 "time given to --listen. If it did send meanwhile: check that the cable is a null-modem one "
                 "and goes to the control's serial port, and the control's baud rate, parity, data and stop "
                 "bits (Haas settings 11, 12, 37, 13; Fanuc parameters 0101-0103)\n";
    return;
  }
  std::cout << "listen: " << guess.bytes << " bytes (NUL leader left out), " << guess.framing_errors
            << " framing errors, " << static_cast<int>(guess.text_share * 100 + 0.5) << "% program text\n";
  if (!guess.peer.empty())
    std::cout << "peer: " << guess.peer << "\n";
  std::cout << "line: " << guess.line << "\n";
  if (guess.profiles.empty())
  {
    std::cout << "profile: none of config/controls/ matches\n";
    return;
  }
  std::cout << "profile:";
  for (size_t i = 0; i < guess.profiles.size(); ++i)
    std::cout << (i ? ", " : " ") << guess.profiles[i];
  std::cout << " (config/controls/<name>.yaml, params_file:= of the node)\n";
}

/// Checks a local port: it opens, and no other process holds it; \returns the exit status.
int doctorLocal(const SerialSettings& settings)
{
  try
  {
    SerialPort port(settings, InputOnOpen::kKeep);
    std::cout << "port " << settings.device << ": opens\n";
    std::cout << "settings applied: " << settings.baud << " baud, " << settings.data_bits << " data bits, parity "
              << toString(settings.parity) << ", " << settings.stop_bits << " stop bit(s), flow control "
              << toString(settings.flow_control) << "\n";
  }
  catch (const LinkError& e)
  {
    std::cout << "port " << settings.device << ": cannot open\n" << e.what() << "\n";
    return 1;
  }
  // A port another program has open is not free for a transfer: the two take each other's bytes.
  const auto holders = processesCompetingFor(settings.device, ::getpid());
  if (!holders.empty())
  {
    std::cout << "port " << settings.device << ": also open in another process, so not free for a transfer "
              << "(two programs on one port take each other's bytes):\n";
    for (const auto& holder : holders)
      std::cout << "  " << describeHolder(holder) << "\n";
    return 1;
  }
  return 0;
}

constexpr const char* kAnotherClient =
    "another client may hold the port: most device servers serve a port to one client at a time and close "
    "the connection of the next (a DNC program, a node on another computer, a terminal session left open); "
    "stop it, or look at the server's connection list (ser2net: its log; Moxa, Lantronix, Digi: the web page's "
    "port status)";

/// What to check, in words, for a device server's port that failed with \p error.
std::string networkHint(const SerialAddress& address, const std::string& error)
{
  const std::string where = address.host + ":" + std::to_string(address.port);
  const std::string ask_mode =
      address.kind == SerialAddress::Kind::kRfc2217
          ? "the server's port mode: rfc2217:// needs the port in RFC 2217 (Telnet COM Port Control) mode "
            "(ser2net: accepter telnet(rfc2217),tcp,PORT; Moxa NPort: operation mode RFC2217); a port in raw TCP "
            "mode is reached with tcp://" +
                where + " and its line is set up on the server"
          : "the server's port mode: tcp:// needs the port in raw TCP mode (ser2net: accepter tcp,PORT; Moxa "
            "NPort: TCP server mode); a port in RFC 2217 mode is reached with rfc2217://" +
                where;
  if (error.find("cannot reach the device server") != std::string::npos)
    return "check: the server's address and the TCP port of the serial port in its configuration, that it is "
           "on and on the network (ping " +
           address.host +
           "), and that no firewall between here and it blocks TCP "
           "port " +
           std::to_string(address.port);
  if (error.find("COM Port Control") != std::string::npos || error.find("binary transmission") != std::string::npos)
    return "check " + ask_mode;
  if (error.find("closed the connection") != std::string::npos)
    return "check: " + std::string(kAnotherClient) + "; or the server restarted meanwhile";
  if (error.find("when asked for") != std::string::npos ||
      error.find("did not answer the setting") != std::string::npos)
    return "check: the server's port lets the client set the line (ser2net: no fixed settings; Moxa: "
           "RFC2217 mode), and that its UART supports the setting named";
  return "check " + ask_mode;
}

/// Bytes that show the port speaks Telnet (it opens with IAC commands) where raw TCP was asked for.
bool looksLikeTelnet(const std::vector<uint8_t>& bytes)
{
  return !bytes.empty() && bytes.front() == rfc2217::kIac;
}

/// Printable text of what a server said before it closed the connection ("Port already in use").
std::string printable(const std::vector<uint8_t>& bytes)
{
  std::string text;
  for (uint8_t byte : bytes)
    text += (byte >= 0x20 && byte < 0x7f) ? static_cast<char>(byte) : ' ';
  const size_t first = text.find_first_not_of(' ');
  const size_t last = text.find_last_not_of(' ');
  return first == std::string::npos ? std::string() : text.substr(first, last - first + 1);
}

/// Checks a device server's port along the network path; \returns the exit status.
int doctorNetwork(const SerialSettings& settings, const SerialAddress& address)
{
  const bool telnet = address.kind == SerialAddress::Kind::kRfc2217;
  const std::string where = address.host + ":" + std::to_string(address.port);
  std::cout << "device server " << where << ", " << (telnet ? "RFC 2217 (Telnet COM Port Control)" : "raw TCP")
            << ": connecting" << std::endl;
  std::unique_ptr<SerialLine> line;
  try
  {
    line = openSerialLine(settings, InputOnOpen::kKeep);
  }
  catch (const LinkError& e)
  {
    std::cout << "port " << settings.device << ": cannot open\n"
              << e.what() << "\n"
              << networkHint(address, e.what()) << "\n";
    return 1;
  }
  std::cout << "connect: ok\n";
  if (auto* rfc2217_line = dynamic_cast<TelnetSerialLine*>(line.get()))
  {
    std::cout << "Telnet negotiation: COM Port Control (RFC 2217) and binary transmission accepted\n";
    std::cout << "line settings the server reports:";
    const auto reported = rfc2217_line->serverSettings();
    for (size_t i = 0; i < reported.size(); ++i)
      std::cout << (i ? ", " : " ") << reported[i];
    std::cout << " (as asked: " << settings.baud << " baud, " << settings.data_bits << " data bits, parity "
              << toString(settings.parity) << ", " << settings.stop_bits << " stop bit(s))\n";
  }
  else
  {
    std::cout << "line settings: the server's own (raw TCP cannot set or read them): its port must be set to "
              << settings.baud << " baud, " << settings.data_bits << " data bits, parity " << toString(settings.parity)
              << ", " << settings.stop_bits << " stop bit(s), as the control is\n";
  }
  // A server that serves one client at a time accepts the next one and closes it at once, often
  // with a word of why: wait a moment to see whether this connection stays.
  std::vector<uint8_t> said;
  const auto until = std::chrono::steady_clock::now() + Milliseconds(500);
  try
  {
    uint8_t buffer[256];
    for (auto now = std::chrono::steady_clock::now(); now < until; now = std::chrono::steady_clock::now())
    {
      const size_t n = line->read(buffer, sizeof buffer, std::chrono::duration_cast<Milliseconds>(until - now));
      said.insert(said.end(), buffer, buffer + n);
    }
  }
  catch (const LinkError& e)
  {
    const std::string text = printable(said);
    std::cout << "port " << settings.device << ": the server closed the connection right after accepting it"
              << (text.empty() ? "" : " (it said: \"" + text + "\")") << "\n"
              << e.what() << "\ncheck: " << kAnotherClient << "\n";
    return 1;
  }
  if (!telnet && looksLikeTelnet(said))
  {
    std::cout << "port " << settings.device << ": the server opened with Telnet commands, so its port is in "
              << "Telnet/RFC 2217 mode: use rfc2217://" << where << " (or set the port to raw TCP)\n";
    return 1;
  }
  std::cout << "port " << settings.device << ": connected and kept: free for a transfer\n";
  return 0;
}
}  // namespace

int runDoctor(const std::vector<std::string>& args)
{
  po::options_description options("cnc_dnc doctor");
  options.add_options()("help,h", "this help")(
      "port,p", po::value<std::string>(),
      "serial device (/dev/ttyUSB0) or device server port (tcp://host:port, rfc2217://host:port)")(
      "baud,b", po::value<unsigned>()->default_value(9600), "baud rate to open and listen at")(
      "parity", po::value<std::string>()->default_value("none"), "none|even|odd")(
      "data-bits", po::value<unsigned>()->default_value(8), "7|8")("stop-bits", po::value<unsigned>()->default_value(1),
                                                                   "1|2")(
      "listen", po::value<double>(), "seconds to listen to the control (press PUNCH/SEND, or start a DPRNT program)");
  po::variables_map vm;
  const char* usage = "usage: cnc_dnc doctor --port DEV [options] [--listen S]\n";
  try
  {
    po::store(po::command_line_parser(args).options(options).run(), vm);
    po::notify(vm);
  }
  catch (const po::error& e)
  {
    std::cerr << "cnc_dnc doctor: " << e.what() << "\n" << usage << options;
    return 2;
  }
  if (vm.count("help"))
  {
    std::cout << usage << options;
    return 0;
  }
  if (!vm.count("port"))
  {
    std::cerr << "cnc_dnc doctor: --port is required\n" << usage << options;
    return 2;
  }
  SerialSettings settings = serialSettingsFrom(vm);
  settings.validate();
  const SerialAddress address = parseSerialAddress(settings.device);
  const int status = address.networked() ? doctorNetwork(settings, address) : doctorLocal(settings);
  if (status != 0)
    return status;
  if (!vm.count("listen"))
    return 0;
  const double seconds = vm["listen"].as<double>();
  if (seconds <= 0)
  {
    std::cerr << "cnc_dnc doctor: --listen must be positive\n";
    return 2;
  }
  std::cout << "listening " << seconds << " s at " << settings.baud
            << " baud, 8 bits without parity (so a parity bit shows as bit 7)" << std::endl;
  const LineGuess guess = listen(settings, seconds);
  printGuess(guess, seconds);
  return guess.bytes > 0 ? 0 : 1;
}
}  // namespace cli
}  // namespace cnc_bridge
