// A scratch folder for one test, removed with everything in it when the test ends, and the
// whole-file helpers of the tests that write programs and read back what a transfer stored.
#pragma once

#include <sys/stat.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <string>

namespace cnc_bridge::test
{
class TempDir
{
 public:
  /// Makes the folder /tmp/<prefix>.XXXXXX.
  explicit TempDir(const std::string& prefix = "cnc_bridge_test") : path("/tmp/" + prefix + ".XXXXXX")
  {
    if (::mkdtemp(path.data()) == nullptr)
      throw std::runtime_error("mkdtemp " + path + ": " + std::strerror(errno));
  }
  ~TempDir()
  {
    std::error_code ignored;
    std::filesystem::remove_all(path, ignored);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  /// The path of \p name inside the folder.
  std::string file(const std::string& name) const { return path + "/" + name; }

  /// Writes \p contents to \p name inside the folder; returns its path.
  std::string write(const std::string& name, const std::string& contents) const
  {
    const std::string target = file(name);
    std::ofstream(target, std::ios::binary) << contents;
    return target;
  }

  std::string path;  ///< the folder
};

/// The whole file ("" when it cannot be read).
inline std::string readFile(const std::string& path)
{
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

inline void writeFile(const std::string& path, const std::string& contents)
{
  std::ofstream(path, std::ios::binary) << contents;
}

inline bool exists(const std::string& path)
{
  struct stat info;
  return ::stat(path.c_str(), &info) == 0;
}
}  // namespace cnc_bridge::test
