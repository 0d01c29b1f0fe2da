// The setpoint sender's real-time request as a user without the rights to it: the sender starts
// anyway, with the normal scheduler, and one warning says what was refused and what allows it.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <string>
#include <vector>

#include "cnc_bridge/at_protocol/sender.h"
#include "cnc_bridge/common/log.h"

namespace ap = cnc_bridge::at_protocol;

namespace
{
/// In a child process without CAP_SYS_NICE, CAP_IPC_LOCK and real-time limits (root drops to
/// nobody, which clears every capability; anyone can lower their own limits), starts and stops a
/// sender with SCHED_FIFO priority 50. \returns the warnings it logged, one per line.
std::vector<std::string> warningsWithoutRealtimeRights()
{
  int out[2];
  EXPECT_EQ(::pipe(out), 0);
  const pid_t child = ::fork();
  if (child == 0)
  {
    ::close(out[0]);
    const rlimit none{0, 0};
    bool ok = ::setrlimit(RLIMIT_RTPRIO, &none) == 0 && ::setrlimit(RLIMIT_MEMLOCK, &none) == 0;
    if (::geteuid() == 0)
    {
      ok = ok && ::setgid(65534) == 0 && ::setuid(65534) == 0;
    }
    std::string lines = ok ? "" : "could not drop the rights\n";
    cnc_bridge::setLogHandler(
        [&](cnc_bridge::LogLevel level, const std::string& text)
        {
          if (level == cnc_bridge::LogLevel::kWarn)
          {
            lines += text + "\n";
          }
        });
    {
      ap::SetpointSender::Options options;
      options.realtime_priority = 50;
      ap::SetpointSender sender(options);
    }
    const ssize_t written = ::write(out[1], lines.data(), lines.size());
    ::_exit(written == static_cast<ssize_t>(lines.size()) ? 0 : 1);
  }
  ::close(out[1]);
  std::string text;
  char buffer[4096];
  for (ssize_t n; (n = ::read(out[0], buffer, sizeof buffer)) > 0;)
  {
    text.append(buffer, static_cast<size_t>(n));
  }
  ::close(out[0]);
  int status = -1;
  EXPECT_EQ(::waitpid(child, &status, 0), child);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
  std::vector<std::string> lines;
  for (size_t start = 0, end; (end = text.find('\n', start)) != std::string::npos; start = end + 1)
  {
    lines.push_back(text.substr(start, end - start));
  }
  return lines;
}
}  // namespace

TEST(SetpointSenderRealtime, WithoutTheRightsItFallsBackWithOneWarningThatSaysWhatAllowsIt)
{
  const std::vector<std::string> warnings = warningsWithoutRealtimeRights();
  ASSERT_EQ(warnings.size(), 1u) << (warnings.empty() ? "" : warnings[0]);
  const std::string& w = warnings[0];
  EXPECT_NE(w.find("SCHED_FIFO priority 50 not granted"), std::string::npos) << w;
  EXPECT_NE(w.find("streaming with the normal scheduler"), std::string::npos) << w;
  // The memory lock is not checked: AddressSanitizer's mlockall does nothing and reports success.
  EXPECT_NE(w.find("CPU idle latency not limited"), std::string::npos) << w;
  EXPECT_NE(w.find("setcap cap_sys_nice,cap_ipc_lock+ep"), std::string::npos) << w;
  EXPECT_NE(w.find("/etc/security/limits.conf"), std::string::npos) << w;
  EXPECT_NE(w.find("rtprio 50"), std::string::npos) << w;
}

TEST(SetpointSenderRealtime, WithoutARealtimeRequestNothingIsAskedAndNothingWarned)
{
  std::vector<std::string> warnings;
  cnc_bridge::setLogHandler(
      [&](cnc_bridge::LogLevel level, const std::string& text)
      {
        if (level == cnc_bridge::LogLevel::kWarn)
        {
          warnings.push_back(text);
        }
      });
  {
    ap::SetpointSender sender(ap::SetpointSender::Options{});
  }
  cnc_bridge::setLogHandler({});
  EXPECT_TRUE(warnings.empty()) << warnings.front();
}
