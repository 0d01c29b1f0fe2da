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
