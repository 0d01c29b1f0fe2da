// A simulator's record of what it received, one line each in a file it appends to from its own
// process (e.g. sim_at_controller --command-log, sim_slave_bus --delivery-log): what the machine
// got, seen from the machine's side. And the ways to read and wait for other files a simulator
// writes: every wait on a file is an inotify wait with a deadline.
#pragma once

#include <poll.h>
#include <sys/inotify.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <stdexcept>
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

namespace detail
{
/// The folders of some files, watched by inotify for what happens to those files. A folder not
/// made yet is watched in its nearest existing ancestor until it appears.
class FileWatch
{
 public:
  explicit FileWatch(const std::vector<std::string>& paths) : fd_(::inotify_init1(IN_CLOEXEC | IN_NONBLOCK))
  {
    if (fd_ < 0)
    {
      throw std::runtime_error(std::string("inotify_init1: ") + std::strerror(errno) +
                               " (check fs.inotify.max_user_instances)");
    }
    for (const std::string& path : paths)
    {
      const std::filesystem::path file(path);
      const std::filesystem::path folder = file.parent_path();
      targets_.push_back(Target{folder.empty() ? std::filesystem::path(".") : folder, file.filename().string()});
    }
    watchFolders();
  }
  ~FileWatch() { ::close(fd_); }
  FileWatch(const FileWatch&) = delete;
  FileWatch& operator=(const FileWatch&) = delete;

  /// \returns true at an event that may concern one of the files, false once \p deadline passed.
  bool waitForChange(std::chrono::steady_clock::time_point deadline)
  {
    for (;;)
    {
      const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0)
      {
        return false;
      }
      pollfd readable{fd_, POLLIN, 0};
      if (::poll(&readable, 1, static_cast<int>(left.count())) > 0 && readEvents())
      {
        return true;
      }
    }
  }

 private:
  static constexpr uint32_t kEvents =
      IN_CREATE | IN_MODIFY | IN_CLOSE_WRITE | IN_MOVED_TO | IN_MOVED_FROM | IN_DELETE | IN_ATTRIB;
  struct Target
  {
    std::filesystem::path folder;
    std::string name;
    int watch = -1;
    bool in_folder = false;  // else watched in an ancestor, waiting for the folder to appear
  };

  void watchFolders()
  {
    for (Target& target : targets_)
    {
      for (std::filesystem::path folder = target.folder; !target.in_folder && !folder.empty();
           folder = folder.parent_path())
      {
        const int watch = ::inotify_add_watch(fd_, folder.c_str(), kEvents);
        if (watch >= 0)
        {
          target.watch = watch;
          target.in_folder = folder == target.folder;
          break;
        }
        if (folder == folder.parent_path())
        {
          break;  // the root: nothing to watch (the wait then ends at its deadline)
        }
      }
    }
  }

  /// Reads the queued events. \returns whether one may concern a file.
  bool readEvents()
  {
    bool relevant = false, rewatch = false;
    alignas(inotify_event) char buffer[8192];
    for (ssize_t size; (size = ::read(fd_, buffer, sizeof buffer)) > 0;)
    {
      for (ssize_t at = 0; at < size;)
      {
        const auto* event = reinterpret_cast<const inotify_event*>(buffer + at);
        at += static_cast<ssize_t>(sizeof(inotify_event) + event->len);
        relevant |= (event->mask & IN_Q_OVERFLOW) != 0;
        for (Target& target : targets_)
        {
          if (target.watch != event->wd)
          {
            continue;
          }
          if (!target.in_folder || (event->mask & IN_IGNORED))
          {
            // Something changed on the way to the folder, or the folder went: watch again.
            target.in_folder = target.in_folder && !(event->mask & IN_IGNORED);
            rewatch = relevant = true;
          }
          else if (event->len > 0 && target.name == event->name)
          {
            relevant = true;
          }
        }
      }
    }
    if (rewatch)
    {
      watchFolders();
    }
    return relevant;
  }

  int fd_;
  std::vector<Target> targets_;
};
}  // namespace detail

/// \brief Waits until \p ready holds, for up to \p seconds, for files another process writes (a
/// simulator's log, its pty link, a file it renames into place), where there is nothing to
/// subscribe to: \p ready is checked at once and again each time inotify reports one of \p paths
/// made, written, closed, renamed, removed or changed in its attributes.
/// \throws std::runtime_error if inotify is not available.
inline bool waitForFiles(const std::vector<std::string>& paths, const std::function<bool()>& ready, double seconds)
{
  const auto deadline =
      std::chrono::steady_clock::now() +
      std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(seconds));
  detail::FileWatch watch(paths);  // before the first look: no change after it is missed
  while (!ready())
  {
    if (!watch.waitForChange(deadline))
    {
      return ready();
    }
  }
  return true;
}

/// \brief waitForFiles() for one file.
inline bool waitForFile(const std::string& path, const std::function<bool()>& ready, double seconds)
{
  return waitForFiles({path}, ready, seconds);
}

/// \brief Waits until every one of \p paths exists (made, or renamed into place), for up to \p
/// seconds. Looks at them with stat() only: a pty link is not opened (that would make its peer see
/// a reader).
inline bool waitUntilAllExist(const std::vector<std::string>& paths, double seconds)
{
  const auto all_there = [&paths]
  {
    struct stat info;
    for (const std::string& path : paths)
    {
      if (::stat(path.c_str(), &info) != 0)
      {
        return false;
      }
    }
    return true;
  };
  return waitForFiles(paths, all_there, seconds);
}

/// \brief waitUntilAllExist() for one path.
inline bool waitUntilExists(const std::string& path, double seconds)
{
  return waitUntilAllExist({path}, seconds);
}

/// \brief Waits until \p ready holds, checked every 20 ms for up to \p seconds: only for what
/// nothing announces and no file shows (a subscriber's count of publishers, a node's process as
/// the master knows it); a file another process writes: waitForFile().
inline bool waitUntil(const std::function<bool()>& ready, double seconds)
{
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < deadline)
  {
    if (ready())
    {
      return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // poll: no event to wait on
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
    std::vector<std::string> found;
    waitForFile(
        path_,
        [&]
        {
          const auto all = lines();
          for (size_t i = mark; i < all.size(); ++i)
          {
            if (all[i] == barrier)
            {
              found.assign(all.begin() + static_cast<long>(mark), all.begin() + static_cast<long>(i) + 1);
              return true;
            }
          }
          return false;
        },
        seconds);
    return found;
  }

  /// \returns true once the log holds more than \p count lines, false after \p seconds.
  bool waitForMoreThan(size_t count, double seconds = 10.0) const
  {
    return waitForFile(
        path_, [&] { return lines().size() > count; }, seconds);
  }

 private:
  std::string path_;
};
}  // namespace line_log
