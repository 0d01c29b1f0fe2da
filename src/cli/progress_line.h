// The progress display of cnc_dnc: on a terminal a bar redrawn in place ten times a second; when
// stderr is a log or a pipe, a plain line once a second (a log should not fill with carriage
// returns). Shared by every subcommand.
#pragma once

#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>

namespace cnc_bridge
{
namespace cli
{
/// \brief One progress line on stderr. Not thread-safe.
class ProgressLine
{
 public:
  explicit ProgressLine(std::string what) : what_(std::move(what)), tty_(::isatty(STDERR_FILENO) == 1) {}
  ~ProgressLine() { finish(); }
  ProgressLine(const ProgressLine&) = delete;
  ProgressLine& operator=(const ProgressLine&) = delete;

  /// \brief Shows \p bytes of \p total (0: unknown) and a detail text ("block 7, 0 retries"),
  /// unless the last update was too recent; \p force shows it anyway (the final state).
  void show(uint64_t bytes, uint64_t total, const std::string& detail, bool force = false)
  {
    const auto now = std::chrono::steady_clock::now();
    const auto interval = tty_ ? std::chrono::milliseconds(100) : std::chrono::milliseconds(1000);
    if (!force && now - last_ < interval)
      return;
    last_ = now;
    std::string text = what_;
    if (total > 0)
    {
      const double fraction = static_cast<double>(bytes) / static_cast<double>(total);
      std::string bar(kWidth, ' ');
      for (int i = 0; i < static_cast<int>(fraction * kWidth) && i < kWidth; ++i)
        bar[i] = '#';
      char numbers[96];
      std::snprintf(numbers, sizeof(numbers), " [%s] %3.0f%% %llu/%llu bytes", bar.c_str(), 100 * fraction,
                    static_cast<unsigned long long>(bytes), static_cast<unsigned long long>(total));
      text += numbers;
    }
    else
    {
      text += " " + std::to_string(bytes) + " bytes";
    }
    if (!detail.empty())
      text += ", " + detail;
    if (tty_)
    {
      std::fprintf(stderr, "\r%s   ", text.c_str());
      drawn_ = true;
    }
    else
    {
      std::fprintf(stderr, "%s\n", text.c_str());
    }
  }

  /// \brief Ends a redrawn line so that what follows starts on a line of its own.
  void finish()
  {
    if (drawn_)
      std::fputc('\n', stderr);
    drawn_ = false;
  }

 private:
  static constexpr int kWidth = 30;
  std::string what_;
  bool tty_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point last_{};
};
}  // namespace cli
}  // namespace cnc_bridge
