// Simulator support: the announcement line.
#include "cnc_bridge/testing/sim_support.h"

#include <iostream>

namespace cnc_bridge
{
namespace sim
{
void announce(const std::string& what, const std::string& where)
{
  std::cout << what << " " << where << std::endl;
}
}  // namespace sim
}  // namespace cnc_bridge
