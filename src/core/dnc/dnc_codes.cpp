// End-of-block names for the drip-feed and backup options.
#include "cnc_bridge/dnc/dnc_codes.h"

#include <cstdio>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace dnc
{
namespace
{
struct NamedEob
{
  const char* name;
  const char* bytes;
};
constexpr NamedEob kEobs[] = {{"lf", "\n"}, {"cr", "\r"}, {"crlf", "\r\n"}, {"lfcr", "\n\r"}, {"lfcrcr", "\n\r\r"}};
}  // namespace

std::string parseEob(const std::string& name)
{
  for (const auto& eob : kEobs)
  {
    if (name == eob.name)
    {
      return eob.bytes;
    }
  }
  throw ConfigError("end of block must be lf, cr, crlf, lfcr or lfcrcr, not '" + name + "'");
}

std::string eobName(const std::string& eob)
{
  for (const auto& named : kEobs)
  {
    if (eob == named.bytes)
    {
      return named.name;
    }
  }
  std::string escaped;
  for (const unsigned char c : eob)
  {
    char hex[8];
    std::snprintf(hex, sizeof(hex), "\\x%02X", c);
    escaped += hex;
  }
  return escaped;
}
}  // namespace dnc
}  // namespace cnc_bridge
