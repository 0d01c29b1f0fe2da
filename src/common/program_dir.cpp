// ProgramDirectory: canonicalise with realpath(3) and compare prefixes on path-component
// boundaries, so "/programs2" is not inside "/programs".
#include "cnc_bridge/common/program_dir.h"

#include <sys/stat.h>
#include <climits>
#include <cstdlib>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace
{
bool canonical(const std::string& path, std::string& out)
{
  char buffer[PATH_MAX];
  if (::realpath(path.c_str(), buffer) == nullptr)
  {
    return false;
  }
  out = buffer;
  return true;
}
}  // namespace

ProgramDirectory::ProgramDirectory(const std::string& root)
{
  struct stat info;
  if (root.empty() || !canonical(root, root_) || ::stat(root_.c_str(), &info) != 0 || !S_ISDIR(info.st_mode))
  {
    throw ConfigError("program directory '" + root + "' does not exist or is not a directory");
  }
}

std::string ProgramDirectory::absolute(const std::string& name) const
{
  if (name.empty())
  {
    throw ConfigError("empty file name");
  }
  return name[0] == '/' ? name : root_ + "/" + name;
}

bool ProgramDirectory::inside(const std::string& path) const
{
  return path.size() > root_.size() && path.compare(0, root_.size(), root_) == 0 &&
         (root_ == "/" || path[root_.size()] == '/');
}

std::string ProgramDirectory::resolveExisting(const std::string& name) const
{
  std::string resolved;
  if (!canonical(absolute(name), resolved))
  {
    throw ConfigError("'" + name + "' does not exist in the program directory " + root_);
  }
  if (!inside(resolved))
  {
    throw ConfigError("'" + name + "' is outside the program directory " + root_ + ": refused");
  }
  return resolved;
}

std::string ProgramDirectory::resolveForWrite(const std::string& name) const
{
  const std::string path = absolute(name);
  const auto slash = path.find_last_of('/');
  const std::string file = path.substr(slash + 1);
  if (file.empty() || file == "." || file == "..")
  {
    throw ConfigError("'" + name + "' does not name a file");
  }
  std::string directory;
  if (!canonical(slash == 0 ? "/" : path.substr(0, slash), directory))
  {
    throw ConfigError("the directory of '" + name + "' does not exist in the program directory " + root_);
  }
  std::string resolved = directory + "/" + file;
  if (directory != root_ && !inside(directory))
  {
    throw ConfigError("'" + name + "' is outside the program directory " + root_ + ": refused");
  }
  // An existing link at the destination must not lead the write elsewhere.
  struct stat info;
  if (::lstat(resolved.c_str(), &info) == 0 && S_ISLNK(info.st_mode))
  {
    std::string target;
    if (!canonical(resolved, target) || !inside(target))
    {
      throw ConfigError("'" + name + "' is a link that leads outside the program directory " + root_ + ": refused");
    }
    return target;
  }
  return resolved;
}
}  // namespace cnc_bridge
