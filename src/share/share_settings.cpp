// share_node's settings (see share_settings.h).
#include "cnc_bridge/share/share_settings.h"

#include <algorithm>
#include <filesystem>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/program_store.h"

namespace cnc_bridge::share
{
std::string shareAddress(const std::string& url, const std::string& serve_dir, const std::string& url_name,
                         const std::string& serve_dir_name)
{
  if (url.empty() == serve_dir.empty())
    throw ConfigError("give exactly one of " + url_name + " (a machine's share) and " + serve_dir_name +
                      " (a folder the PC serves to the controls), not " + (url.empty() ? "neither" : "both"));
  if (!url.empty())
    return url;
  if (serve_dir.compare(0, 6, "smb://") == 0)
    throw ConfigError(serve_dir_name + " is a local folder the PC's Samba serves, not " + serve_dir +
                      ": give a machine's share as ~url");
  if (!std::filesystem::is_directory(serve_dir))
    throw ConfigError(serve_dir_name + " " + serve_dir +
                      " is not a folder: create it and serve it with Samba (config/share/served_share.smb.conf)");
  return serve_dir;
}

std::string requestsAddress(const std::string& address, const std::string& folder)
{
  programs::checkName(folder);
  return address + "/" + folder;
}

std::string archiveDir(const std::optional<std::string>& given, const std::string& program_root)
{
  return given ? *given : program_root + ".archive";
}

unsigned archiveKeep(int given)
{
  return static_cast<unsigned>(std::max(1, given));
}
}  // namespace cnc_bridge::share
