// The protected program range on cnc_dnc's command line: every subcommand that sends a program to
// a control (send, drip, send --share) refuses one whose number lies in the range (Haas keeps its
// probing/WIPS and OEM macros in O08000-O09999) unless --allow-protected is given.
#pragma once

#include <boost/program_options.hpp>
#include <string>

#include "cnc_bridge/programs/program_name.h"

namespace cnc_bridge
{
namespace cli
{
inline void addProtectedOptions(boost::program_options::options_description& options)
{
  namespace po = boost::program_options;
  options.add_options()("allow-protected", po::bool_switch(), "send a program in the protected range anyway")(
      "protected-range", po::value<std::string>()->default_value("O08000-O09999"),
      "program numbers never sent without --allow-protected (\"\" for none)")(
      "name-pattern", po::value<std::string>()->default_value("O%05d.nc"),
      "how the control names program files (printf style, one %d or %0Nd)");
}

inline programs::ProtectedRange protectedRange(const boost::program_options::variables_map& vm)
{
  return programs::ProtectedRange(vm["protected-range"].as<std::string>(), vm["allow-protected"].as<bool>(),
                                  "--allow-protected");
}

/// \throws DisabledError if the file at \p path is a protected program (by its name or its text).
inline void checkProtected(const boost::program_options::variables_map& vm, const std::string& path,
                           const std::string& sent_name = "")
{
  programs::checkProtectedFile(protectedRange(vm), programs::NamePattern(vm["name-pattern"].as<std::string>()), path,
                               sent_name);
}
/// \throws DisabledError if \p contents, read from \p path to be sent, are a protected program.
inline void checkProtectedContents(const boost::program_options::variables_map& vm, const std::string& path,
                                   const std::string& contents)
{
  const std::string name = path.substr(path.find_last_of('/') + 1);
  protectedRange(vm).checkHeader(path, programs::NamePattern(vm["name-pattern"].as<std::string>()).number(name),
                                 programs::readHeader(contents));
}
}  // namespace cli
}  // namespace cnc_bridge
