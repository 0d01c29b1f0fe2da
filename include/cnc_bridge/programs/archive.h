// The program archive: every version of every program that went to or came from a machine, kept
// beside the program directory, so that "what ran on the machine last Tuesday" and "what did the
// operator change at the control" have answers. One folder per program:
//
//     <archive>/O01234.nc/v0001.nc      the content, byte for byte
//     <archive>/O01234.nc/v0001.meta    time, node, machine, direction, size, crc32 (key = value)
//
// A version identical to one already kept is not stored again; the oldest versions beyond `keep`
// are removed. Files are written atomically (AtomicFileWriter), 0640 or narrower (a version is
// never more readable than the program it keeps), in folders created 0750; no symbolic link in
// the archive is followed (a link planted as a program's folder or a version is refused or skipped).
#pragma once

#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/common/atomic_file.h"

namespace cnc_bridge::programs
{
/// \brief The mode of the archive's folders (before the umask).
constexpr unsigned kArchiveFolderMode = 0750;

/// \brief Where a version came from.
struct VersionSource
{
  std::string node;       ///< "dnc_node", "share_node", "cnc_dnc"
  std::string machine;    ///< "haas_vf2"
  std::string direction;  ///< "sent" (to the machine) or "received" (from it)
};

/// \brief One kept version of a program.
struct ArchiveVersion
{
  unsigned number = 0;  ///< 1, 2, ... in the order they were kept
  int64_t time = 0;     ///< seconds since the epoch
  VersionSource source;
  uint64_t size = 0;
  std::string crc32;  ///< 8 hex digits, as `crc32` (libarchive-zip-perl) or Python's zlib.crc32 print it
  std::string path;   ///< the content's file
};

/// \brief The archive of one program directory. Thread-safe: add() calls from several threads of one
/// process (a transfer, the hybrid share's collection) are serialised.
class ProgramArchive
{
 public:
  /// \param root the archive folder, created if missing. \param keep versions kept per program (>= 1).
  /// \throws ConfigError if it cannot be created.
  ProgramArchive(std::string root, unsigned keep = 20);

  /// \brief Keeps \p content as the next version of \p name unless a kept version is identical,
  /// with \p mode (the kept program's permission bits; no more than kProgramFileMode is given).
  /// \returns the new version, or nothing if the content was kept already.
  /// \throws ConfigError for a bad name, Error if it cannot be written.
  std::optional<ArchiveVersion> add(const std::string& name, const std::string& content, const VersionSource& source,
                                    unsigned mode = kProgramFileMode);
  /// \brief The kept versions of \p name, oldest first (empty if none).
  std::vector<ArchiveVersion> history(const std::string& name) const;
  /// \brief Version \p number of \p name. \throws ConfigError naming the versions there are.
  ArchiveVersion version(const std::string& name, unsigned number) const;
  /// \brief A unified diff (diff -u) from \p from_path to \p to_path, labelled; "" when identical.
  /// \throws Error if diff cannot run.
  static std::string diff(const std::string& from_path, const std::string& from_label, const std::string& to_path,
                          const std::string& to_label);
  const std::string& root() const { return root_; }

 private:
  std::string folder(const std::string& name) const;
  std::string root_;
  unsigned keep_;
  std::mutex add_mutex_;  ///< one version numbered and written at a time
};

/// \brief The unified diff a user asks for by version numbers: \p from (0: the newest kept version)
/// to \p to (0: the current file at \p current_path). "" when identical.
/// \throws ConfigError for a version not kept or a missing current file, Error if diff fails.
std::string compareVersions(const ProgramArchive& archive, const std::string& name, unsigned from, unsigned to,
                            const std::string& current_path);

/// \brief CRC-32 (IEEE 802.3, as zlib) of \p data as 8 hex digits.
std::string crc32Hex(const std::string& data);
}  // namespace cnc_bridge::programs
