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
#include <termios.h>
#include <unistd.h>

#include <boost/program_options.hpp>
#include <chrono>
#include <iostream>
#include <string>
#include <vector>

#include "cnc_bridge/common/error.h"
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
/// with framing errors marked by the driver.
LineGuess listen(const SerialSettings& asked, double seconds)
{
  SerialSettings raw = asked;
  raw.data_bits = 8;
  raw.parity = Parity::kNone;
  raw.flow_control = FlowControl::kNone;
  SerialPort port(raw, InputOnOpen::kKeep);
  struct termios tio;
  if (::tcgetattr(port.nativeHandle(), &tio) == 0)
  {
    tio.c_iflag = (tio.c_iflag | PARMRK) & ~(IGNPAR | ISTRIP);
    ::tcsetattr(port.nativeHandle(), TCSANOW, &tio);
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
  const size_t errors = takeErrorMarks(bytes);
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
}  // namespace

int runDoctor(const std::vector<std::string>& args)
{
  po::options_description options("cnc_dnc doctor");
  options.add_options()("help,h", "this help")("port,p", po::value<std::string>(), "serial device, e.g. /dev/ttyUSB0")(
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
