// The G-code reading options every node that parses programs takes from its private parameters,
// so that ethernut_node and at_controller_node read a shop's programs the same way.
#pragma once

#include <ros/node_handle.h>

#include <memory>
#include <string>

#include "cnc_bridge/gcode/gcode.h"

namespace cnc_bridge
{
namespace params
{
/// \brief Reads ~gcode_dialect (haas, fanuc or linuxcnc; default haas) and ~tool_table (a LinuxCNC
/// .tbl or a .yaml file with tool diameters for G41/G42; none: such programs are refused) into
/// \p options.
/// \throws ConfigError naming the parameter for an unknown dialect or an unreadable tool table.
inline void gcodeOptions(const ros::NodeHandle& pnh, gcode::ParserOptions& options)
{
  std::string dialect;
  pnh.param<std::string>("gcode_dialect", dialect, "haas");
  try
  {
    options.dialect = gcode::parseDialect(dialect);
  }
  catch (const ConfigError& e)
  {
    throw ConfigError(pnh.resolveName("gcode_dialect") + ": " + e.what());
  }
  std::string tool_table;
  pnh.param<std::string>("tool_table", tool_table, "");
  if (!tool_table.empty())
  {
    options.tool_table = std::make_shared<gcode::ToolTable>(gcode::ToolTable::load(tool_table));
  }
}
}  // namespace params
}  // namespace cnc_bridge
