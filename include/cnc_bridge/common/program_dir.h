// Confinement of file names to a program directory. Nodes that read or write NC programs on
// request (a service call, an action goal) accept only names that resolve inside `~program_dir`:
// no `..` out of it, no absolute path elsewhere, no symbolic link that points outside. A link
// whose target is inside the directory is allowed (it names that file). Only regular files are
// programs: a directory, FIFO, socket or device where a program belongs is refused by name.
#pragma once

#include <sys/types.h>

#include <string>

#include "cnc_bridge/common/regular_file.h"  // fileKind()

namespace cnc_bridge
{
/// \brief Refuses a requested file name no control or file system takes, before it is used or
/// repeated anywhere: empty, longer than 1024 bytes or with a part longer than 255 (NAME_MAX), a
/// control character, or bytes that are not UTF-8. \throws ConfigError showing the name shortened
/// and escaped (printableName()).
void checkRequestedName(const std::string& name);

/// \brief \p name as it may be shown in a message or a log line: at most 80 characters, bytes
/// outside printable ASCII as \xNN, "..." where it was cut.
std::string printableName(const std::string& name);

/// \brief A directory that requested file names must stay inside. Thread-safe (immutable).
class ProgramDirectory
{
 public:
  /// \throws ConfigError if \p root is not an existing directory.
  explicit ProgramDirectory(const std::string& root);

  /// \brief Resolves a file that must already exist, following symbolic links.
  /// \param name relative to the root, or absolute but inside it.
  /// \returns the canonical absolute path (no link in it: open it with openRegularFile()).
  /// \throws ConfigError naming the request if it resolves outside the root, does not exist or is
  /// not a regular file.
  std::string resolveExisting(const std::string& name) const;

  /// \brief Resolves a file to be created or replaced: its directory must exist inside the root,
  /// and if the file exists (or is a link) it must resolve inside the root too, to a regular file.
  /// \throws ConfigError as resolveExisting().
  std::string resolveForWrite(const std::string& name) const;

  const std::string& root() const { return root_; }

 private:
  std::string absolute(const std::string& name) const;
  bool inside(const std::string& canonical) const;

  std::string root_;  // canonical, no trailing slash
};

/// \brief Opens \p name in the folder open as \p dir_fd (AT_FDCWD: relative to the current one) for
/// reading, without following a link at it and without waiting on a FIFO. \p shown names it in
/// messages. \returns the descriptor (the caller closes it), or -1 with errno ENOENT if there is no
/// such file. \throws ConfigError if it is a link or not a regular file ("... is a directory, not
/// a program file"), Error on any other failure.
int openRegularFile(int dir_fd, const std::string& name, const std::string& shown);

/// \brief The whole regular file \p path (a link at its last component refused, openRegularFile()),
/// and its permission bits in \p mode if given. \throws ConfigError (also if missing), Error.
std::string readRegularFile(const std::string& path, mode_t* mode = nullptr);

/// \brief Everything left in the open file \p fd. \throws Error naming \p shown.
std::string readAll(int fd, const std::string& shown);
}  // namespace cnc_bridge
