// sim_haas_serial: a simulated Haas serial port on a pty. The mode picks the behaviour; each mode
// prints "sim_haas_serial pty <path>" as its first line and stops cleanly on SIGINT/SIGTERM.
#include <iostream>

#include "sim/haas_serial/modes.h"

namespace cnc_bridge
{
namespace sim
{
std::map<std::string, ModeInfo>& modes()
{
  static std::map<std::string, ModeInfo> registry;
  return registry;
}
}  // namespace sim
}  // namespace cnc_bridge

int main(int argc, char** argv)
{
  const auto& modes = cnc_bridge::sim::modes();
  const std::string mode = argc > 1 ? argv[1] : "";
  const auto found = modes.find(mode);
  if (found == modes.end())
  {
    std::cerr << "usage: sim_haas_serial MODE [options]   (MODE --help for its options)\nmodes:\n";
    for (const auto& entry : modes)
    {
      std::cerr << "  " << entry.first << "\t" << entry.second.summary << "\n";
    }
    return mode == "--help" || mode == "-h" ? 0 : 2;
  }
  return found->second.run(std::vector<std::string>(argv + 2, argv + argc));
}
