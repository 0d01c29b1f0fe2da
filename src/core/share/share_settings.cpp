// share_node's settings (see share_settings.h).
#include "cnc_bridge/share/share_settings.h"

#include <algorithm>
#include <filesystem>
#include <utility>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/program_store.h"

namespace cnc_bridge::share
{
namespace
{
/// Where the user information of \p address is: [begin, end) before its '@' ({npos, npos} if none).
std::pair<size_t, size_t> userInformation(const std::string& address)
{
  const auto scheme = address.find("://");
  if (scheme == std::string::npos)
    return {std::string::npos, std::string::npos};
  const size_t begin = scheme + 3;
  const size_t authority_end = std::min(address.find('/', begin), address.size());
  const auto at = address.rfind('@', authority_end);
  if (at == std::string::npos || at < begin)
    return {std::string::npos, std::string::npos};
  return {begin, at};
}
}  // namespace

void checkMachineName(const std::string& name, const std::string& given_as)
{
  const bool control =
      std::any_of(name.begin(), name.end(), [](char c) { return static_cast<unsigned char>(c) < 0x20; });
  if (name.empty() || name == "." || name == ".." || name.find('/') != std::string::npos || control)
  {
    throw ConfigError(given_as + ": '" + name + "' cannot be a machine's folder on the NAS (no '/', '.', '..', " +
                      "control character or empty name): name the machine as in the cell (haas_vf2)");
  }
}

void refusePassword(const std::string& address, const std::string& given_as)
{
  const auto [begin, end] = userInformation(address);
  if (begin == std::string::npos || address.find(':', begin) >= end)
    return;
  throw ConfigError(given_as +
                    " holds user information with a password (user:password@): refused, and not repeated here. A "
                    "password never goes in an address, which logs, process lists and the parameter server show: give "
                    "smb://user@host/share (or no user) and put the password in a credentials file in smbclient's "
                    "format (username = ..., password = ...; chmod 600), named by ~credentials_file or --credentials");
}

std::string shownAddress(const std::string& address)
{
  const auto [begin, end] = userInformation(address);
  if (begin == std::string::npos || address.find(':', begin) >= end)
    return address;
  return address.substr(0, begin) + "***" + address.substr(end);
}

std::string shareAddress(const std::string& url, const std::string& serve_dir, const std::string& url_name,
                         const std::string& serve_dir_name)
{
  if (url.empty() == serve_dir.empty())
    throw ConfigError("give exactly one of " + url_name + " (a machine's share) and " + serve_dir_name +
                      " (a folder the PC serves to the controls), not " + (url.empty() ? "neither" : "both"));
  refusePassword(url, url_name);
  refusePassword(serve_dir, serve_dir_name);
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
