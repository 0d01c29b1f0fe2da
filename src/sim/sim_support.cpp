// Simulator support: the announcement line, the pid file.
#include "sim/sim_support.h"

#include <unistd.h>

#include <fstream>
#include <iostream>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace sim
{
void announce(const std::string& what, const std::string& where)
{
  std::cout << what << " " << where << std::endl;
}

void writePidFile(const std::string& path)
{
  std::ofstream out(path, std::ios::trunc);
  out << ::getpid() << "\n";
  if (!out.flush())
  {
    throw ConfigError("--pid-file: cannot write " + path);
  }
}
}  // namespace sim
}  // namespace cnc_bridge
