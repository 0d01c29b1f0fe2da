// ProgramDirectory: canonicalise with realpath(3) and compare prefixes on path-component
// boundaries, so "/programs2" is not inside "/programs".
#include "cnc_bridge/common/program_dir.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>

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

/// Refuses what is at \p path if it exists and is not a regular file.
void checkRegular(const std::string& path, const std::string& name)
{
  struct stat info;
  if (::stat(path.c_str(), &info) == 0 && !S_ISREG(info.st_mode))
    throw ConfigError("'" + name + "' is " + fileKind(info.st_mode) + ", not a program file: refused");
}
}  // namespace

int openRegularFile(int dir_fd, const std::string& name, const std::string& shown)
{
  // O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer.
  const int fd = ::openat(dir_fd, name.c_str(), O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0)
  {
    const int error = errno;
    struct stat info;
    if (error == ENOENT)
      return -1;
    if ((error == ELOOP || error == ENXIO) && ::fstatat(dir_fd, name.c_str(), &info, AT_SYMLINK_NOFOLLOW) == 0)
      throw ConfigError(shown + " is " + fileKind(info.st_mode) + ", not a program file: refused");
    throw Error("cannot read " + shown + ": " + std::strerror(error));
  }
  struct stat info;
  if (::fstat(fd, &info) != 0 || !S_ISREG(info.st_mode))
  {
    const std::string kind = fileKind(info.st_mode);
    ::close(fd);
    throw ConfigError(shown + " is " + kind + ", not a program file: refused");
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  return fd;
}

std::string readAll(int fd, const std::string& shown)
{
  std::string data;
  char buffer[65536];
  for (;;)
  {
    const ssize_t n = ::read(fd, buffer, sizeof(buffer));
    if (n < 0 && errno == EINTR)
      continue;
    if (n < 0)
      throw Error("reading " + shown + ": " + std::strerror(errno));
    if (n == 0)
      return data;
    data.append(buffer, static_cast<size_t>(n));
  }
}

std::string readRegularFile(const std::string& path, mode_t* mode)
{
  const int fd = openRegularFile(AT_FDCWD, path, path);
  if (fd < 0)
    throw ConfigError(path + " does not exist");
  struct stat info;
  if (mode != nullptr)
    *mode = ::fstat(fd, &info) == 0 ? (info.st_mode & 07777) : 0;
  try
  {
    std::string data = readAll(fd, path);
    ::close(fd);
    return data;
  }
  catch (...)
  {
    ::close(fd);
    throw;
  }
}

ProgramDirectory::ProgramDirectory(const std::string& root)
{
  struct stat info;
  if (root.empty() || !canonical(root, root_) || ::stat(root_.c_str(), &info) != 0 || !S_ISDIR(info.st_mode))
  {
    throw ConfigError("program directory '" + root + "' does not exist or is not a directory");
  }
}

namespace
{
constexpr size_t kMaxNameBytes = 1024;
constexpr size_t kMaxPartBytes = 255;  // NAME_MAX of Linux file systems
constexpr size_t kShownCharacters = 80;

/// Whether \p text is well-formed UTF-8 (no overlong forms, no surrogates, at most U+10FFFF).
bool isUtf8(const std::string& text)
{
  size_t i = 0;
  while (i < text.size())
  {
    const auto byte = [&](size_t k) { return static_cast<unsigned char>(text[k]); };
    const unsigned char lead = byte(i);
    size_t length = 0;
    uint32_t code = 0, minimum = 0;
    if (lead < 0x80)
      length = 1, code = lead;
    else if ((lead & 0xe0) == 0xc0)
      length = 2, code = lead & 0x1f, minimum = 0x80;
    else if ((lead & 0xf0) == 0xe0)
      length = 3, code = lead & 0x0f, minimum = 0x800;
    else if ((lead & 0xf8) == 0xf0)
      length = 4, code = lead & 0x07, minimum = 0x10000;
    else
      return false;
    if (i + length > text.size())
      return false;
    for (size_t k = 1; k < length; ++k)
    {
      if ((byte(i + k) & 0xc0) != 0x80)
        return false;
      code = (code << 6) | (byte(i + k) & 0x3f);
    }
    if (code < minimum || code > 0x10ffff || (code >= 0xd800 && code <= 0xdfff))
      return false;
    i += length;
  }
  return true;
}
}  // namespace

std::string printableName(const std::string& name)
{
  std::string shown;
  for (size_t i = 0; i < name.size() && i < kShownCharacters; ++i)
  {
    const auto c = static_cast<unsigned char>(name[i]);
    if (c >= 0x20 && c < 0x7f)
    {
      shown += static_cast<char>(c);
      continue;
    }
    char escaped[8];
    std::snprintf(escaped, sizeof escaped, "\\x%02x", c);
    shown += escaped;
  }
  return name.size() > kShownCharacters ? shown + "..." : shown;
}

void checkRequestedName(const std::string& name)
{
  if (name.empty())
    throw ConfigError("empty file name: name the program file");
  const std::string shown = "'" + printableName(name) + "'";
  if (name.size() > kMaxNameBytes)
    throw ConfigError("file name " + shown + " is " + std::to_string(name.size()) + " bytes long, more than " +
                      std::to_string(kMaxNameBytes) + ": refused");
  size_t part_start = 0;
  for (size_t i = 0; i <= name.size(); ++i)
  {
    if (i < name.size() && name[i] != '/')
      continue;
    if (i - part_start > kMaxPartBytes)
      throw ConfigError("file name " + shown + " has a part longer than " + std::to_string(kMaxPartBytes) +
                        " bytes, the file system's limit: refused");
    part_start = i + 1;
  }
  for (const char c : name)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f)
      throw ConfigError("file name " + shown + " holds a control character: refused");
  if (!isUtf8(name))
    throw ConfigError("file name " + shown + " is not UTF-8 text: refused");
}

std::string ProgramDirectory::absolute(const std::string& name) const
{
  checkRequestedName(name);
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
  checkRegular(resolved, name);
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
    checkRegular(target, name);
    return target;
  }
  checkRegular(resolved, name);
  return resolved;
}
}  // namespace cnc_bridge
