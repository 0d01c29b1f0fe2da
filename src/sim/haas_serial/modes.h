// sim_haas_serial is one simulated Haas RS-232 port with several behaviours, one per mode
// (`sim_haas_serial MODE [options]`). Each mode lives in its own file under src/sim/haas_serial/
// and registers itself with a static SimMode object, so modes are added without touching main().
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace cnc_bridge
{
namespace sim
{
/// A mode's entry point: receives the arguments after the mode name, returns the exit status.
using ModeMain = std::function<int(const std::vector<std::string>& args)>;

struct ModeInfo
{
  std::string summary;
  ModeMain run;
};

/// \brief The registered modes, by name.
std::map<std::string, ModeInfo>& modes();

/// \brief Registers a mode at static-initialisation time:
///   static cnc_bridge::sim::SimMode xmodem("xmodem", "XModem peer as the Haas of OpenDNC's capture", &runXmodem);
struct SimMode
{
  SimMode(const std::string& name, const std::string& summary, ModeMain run)
  {
    modes()[name] = ModeInfo{summary, std::move(run)};
  }
};
}  // namespace sim
}  // namespace cnc_bridge
