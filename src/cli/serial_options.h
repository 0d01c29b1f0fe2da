// The serial line settings every cnc_dnc subcommand reads from its command line (--port, --baud,
// --parity, --data-bits, --stop-bits: Haas settings 11, 12, 37, 13; --wire-trace DIR where a
// subcommand offers it).
#pragma once

#include <boost/program_options.hpp>
#include <string>

#include "cnc_bridge/transport/serial_settings.h"

namespace cnc_bridge
{
namespace cli
{
/// \brief --port (required), --baud, --parity, --data-bits, --stop-bits (Haas settings 11, 12, 37,
/// 13) and --wire-trace: the serial options of send, receive and replay.
inline boost::program_options::options_description serialOptions()
{
  namespace po = boost::program_options;
  po::options_description options("serial port");
  options.add_options()("port,p", po::value<std::string>()->required(),
                        "serial device (/dev/ttyUSB0) or device server port (tcp://host:port, rfc2217://host:port)")(
      "baud,b", po::value<unsigned>()->default_value(115200), "baud rate (Haas setting 11)")(
      "parity", po::value<std::string>()->default_value("none"), "none|even|odd (Haas setting 12)")(
      "data-bits", po::value<unsigned>()->default_value(8), "7|8 (Haas setting 37)")(
      "stop-bits", po::value<unsigned>()->default_value(1), "1|2 (Haas setting 13)")(
      "wire-trace", po::value<std::string>(),
      "write every byte of the line, both ways, to a trace file in this folder (cnc_dnc replay plays it back)");
  return options;
}

/// \brief The line settings from parsed options; flow control is left to the subcommand.
/// \throws ConfigError for an invalid value.
inline SerialSettings serialSettingsFrom(const boost::program_options::variables_map& vm)
{
  SerialSettings s;
  s.device = vm["port"].as<std::string>();
  s.baud = vm["baud"].as<unsigned>();
  s.parity = parseParity(vm["parity"].as<std::string>());
  s.data_bits = vm["data-bits"].as<unsigned>();
  s.stop_bits = vm["stop-bits"].as<unsigned>();
  if (vm.count("wire-trace") != 0)
  {
    s.wire_trace.dir = vm["wire-trace"].as<std::string>();
  }
  return s;
}
}  // namespace cli
}  // namespace cnc_bridge
