// A simulator's record of what it received, one line each in a file it appends to from its own
// process (e.g. sim_at_controller --command-log, sim_slave_bus --delivery-log): what the machine
// got, seen from the machine's side. And the two ways to read other files a simulator writes.
#pragma once

#include <chrono>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace line_log
{
/// \brief The whole content of \p path ("" if it cannot be read).
inline std::string readFile(const std::string& path)
{
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

/// \brief Waits until \p ready holds, checked every 20 ms for up to \p seconds: for files a
/// simulator writes or a node's process, where there is nothing to subscribe to.
inline bool waitUntil(const std::function<bool()>& ready, double seconds)
{
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < deadline)
  {
    if (ready())
    {
      return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // poll: another process writes the file
  }
  return ready();
}

/// \brief The lines of one log file. A test marks the log (the number of lines so far), makes its
/// requests, then waits for a line that must come after them (a barrier): the link keeps order,
/// so once the barrier is in the log, everything sent before it is there too.
class LineLog
{
 public:
  explicit LineLog(std::string path) : path_(std::move(path)) {}

  /// The lines received so far.
  std::vector<std::string> lines() const
  {
    std::vector<std::string> result;
    std::ifstream in(path_);
    for (std::string line; std::getline(in, line);)
    {
      result.push_back(line);
    }
    return result;
  }

  /// The lines after the first \p mark lines up to and including \p barrier, once it arrived
  /// (within \p seconds); empty if it did not.
  std::vector<std::string> linesUntil(size_t mark, const std::string& barrier, double seconds = 10.0) const
  {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    do
    {
      const auto all = lines();
      for (size_t i = mark; i < all.size(); ++i)
      {
        if (all[i] == barrier)
        {
          return {all.begin() + static_cast<long>(mark), all.begin() + static_cast<long>(i) + 1};
        }
      }
      // The simulator writes the file from another process; there is nothing to wait on but the file.
      std::this_thread::sleep_for(std::chrono::milliseconds(20));  // poll
    } while (std::chrono::steady_clock::now() < deadline);
    return {};
  }

  /// \returns true once the log holds more than \p count lines, false after \p seconds.
  bool waitForMoreThan(size_t count, double seconds = 10.0) const
  {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    while (lines().size() <= count)
    {
      if (std::chrono::steady_clock::now() >= deadline)
      {
        return false;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));  // poll, as in linesUntil()
    }
    return true;
  }

 private:
  std::string path_;
};
}  // namespace line_log
