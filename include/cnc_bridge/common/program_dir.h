// Confinement of file names to a program directory. Nodes that read or write NC programs on
// request (a service call, an action goal) accept only names that resolve inside `~program_dir`:
// no `..` out of it, no absolute path elsewhere, no symbolic link that points outside.
#pragma once

#include <string>

namespace cnc_bridge
{
/// \brief A directory that requested file names must stay inside. Thread-safe (immutable).
class ProgramDirectory
{
 public:
  /// \throws ConfigError if \p root is not an existing directory.
  explicit ProgramDirectory(const std::string& root);

  /// \brief Resolves a file that must already exist, following symbolic links.
  /// \param name relative to the root, or absolute but inside it.
  /// \returns the canonical absolute path.
  /// \throws ConfigError naming the request if it resolves outside the root or does not exist.
  std::string resolveExisting(const std::string& name) const;

  /// \brief Resolves a file to be created or replaced: its directory must exist inside the root,
  /// and if the file exists (or is a link) it must resolve inside the root too.
  /// \throws ConfigError as resolveExisting().
  std::string resolveForWrite(const std::string& name) const;

  const std::string& root() const { return root_; }

 private:
  std::string absolute(const std::string& name) const;
  bool inside(const std::string& canonical) const;

  std::string root_;  // canonical, no trailing slash
};
}  // namespace cnc_bridge
