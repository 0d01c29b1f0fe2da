// Reading a file given by a caller (a program to send, a request file, a program's head). Only a
// regular file is read: a FIFO would block the reader until someone writes to it (a node's service
// thread wedged), a device could be read for ever, and a directory is no program. The file is
// opened without blocking, checked with fstat on the descriptor that is then read (nothing can be
// swapped in between), and read in pieces, so memory stays bounded whatever its size.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace cnc_bridge
{
/// \brief A regular file open for reading. Not thread-safe.
class RegularFile
{
 public:
  /// \throws ConfigError if \p path cannot be opened or is not a regular file (the message says
  /// what it is: a directory, a FIFO, a device...).
  explicit RegularFile(const std::string& path);
  ~RegularFile();
  RegularFile(const RegularFile&) = delete;
  RegularFile& operator=(const RegularFile&) = delete;

  /// \brief The size when opened.
  uint64_t size() const { return size_; }
  const std::string& path() const { return path_; }
  /// \brief Reads up to \p size bytes at \p offset (fewer only at the end). \throws Error.
  size_t readAt(uint64_t offset, char* data, size_t size) const;
  /// \brief Reads the next up to \p size bytes (fewer only at the end: 0 there). \throws Error.
  size_t read(char* data, size_t size);
  /// \brief The whole file. \throws ConfigError naming \p limit_name if it holds more than \p max_bytes.
  std::string readAll(uint64_t max_bytes, const std::string& limit_name);

 private:
  std::string path_;
  int fd_ = -1;
  uint64_t size_ = 0;
  uint64_t offset_ = 0;
};

/// \brief Reads up to \p size bytes at \p offset of the open file \p fd (fewer only at its end),
/// retrying short reads and interruptions. \throws Error naming \p path.
size_t readFully(int fd, uint64_t offset, char* data, size_t size, const std::string& path);

/// \brief What kind of file \p mode (a stat st_mode) is, in words: "a directory", "a FIFO"...
std::string fileKind(unsigned mode);
}  // namespace cnc_bridge
