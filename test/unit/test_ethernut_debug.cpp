// The board's serial debug channel: the splitter (line ends, garbage escaped, an oversize line cut
// and counted with memory bounded, the last words before the link went away) and the channel over
// a pty opened through the link factory, including a port that vanishes and comes back.
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "cnc_bridge/ethernut/debug_channel.h"
#include "temp_dir.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using namespace cnc_bridge::ethernut;

namespace
{
std::vector<DebugLine> split(DebugLineSplitter& splitter, const std::string& bytes)
{
  std::vector<DebugLine> lines;
  splitter.feed(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size(),
                [&](const DebugLine& line) { lines.push_back(line); });
  return lines;
}

std::vector<std::string> texts(const std::vector<DebugLine>& lines)
{
  std::vector<std::string> result;
  for (const DebugLine& line : lines)
  {
    result.push_back(line.display());
  }
  return result;
}
}  // namespace

TEST(EthernutDebugSplitter, EveryLineEndSplitsAndEmptyLinesAreOnlyCounted)
{
  DebugLineSplitter splitter;
  const auto lines = split(splitter, "1 TCP GUI accept 1\r\n2 GUI TCP init 78\n3 a\r4 b\n\r5 c\r\n\r\n");
  EXPECT_EQ(texts(lines), (std::vector<std::string>{"1 TCP GUI accept 1", "2 GUI TCP init 78", "3 a", "4 b", "5 c"}));
  EXPECT_EQ(splitter.stats().lines, 5u);
  EXPECT_EQ(splitter.stats().empty_lines, 2u);  // the CR of "\n\r" and the second CR LF
  EXPECT_EQ(splitter.pending(), 0u);
}

TEST(EthernutDebugSplitter, ALineSplitAcrossFeedsIsDeliveredWhole)
{
  DebugLineSplitter splitter;
  EXPECT_TRUE(split(splitter, "2 GUI TC").empty());
  EXPECT_EQ(texts(split(splitter, "P reset 0\r")), (std::vector<std::string>{"2 GUI TCP reset 0"}));
  EXPECT_TRUE(split(splitter, "\n").empty());  // the LF of the CR LF split across two reads
  EXPECT_EQ(splitter.stats().empty_lines, 0u);
}

TEST(EthernutDebugSplitter, GarbageIsEscapedNotDroppedAndTheLineAroundItKept)
{
  DebugLineSplitter splitter;
  const std::string bytes = std::string("ok\x01\x00", 4) + "\xFF\x7F" + "a\\b\tc\r\n";
  const auto lines = split(splitter, bytes);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0].text, "ok\\x01\\x00\\xFF\\x7Fa\\\\b\tc");
  EXPECT_FALSE(lines[0].cut);
  EXPECT_EQ(splitter.stats().escaped_bytes, 4u);
}

TEST(EthernutDebugSplitter, AnOversizeLineIsCutOnceCountedAndTheNextLineIsWhole)
{
  DebugLineSplitter splitter(16);
  const auto lines = split(splitter, std::string(40, 'x') + "\r\nnext line\r\n");
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[0].text, std::string(16, 'x'));
  EXPECT_TRUE(lines[0].cut);
  EXPECT_EQ(lines[0].display(), std::string(16, 'x') + " [cut]");
  EXPECT_EQ(lines[1].display(), "next line");
  EXPECT_EQ(splitter.stats().cut_lines, 1u);
  EXPECT_EQ(splitter.stats().dropped_bytes, 24u);
  EXPECT_EQ(splitter.stats().lines, 2u);
}

TEST(EthernutDebugSplitter, AnEscapeThatDoesNotFitCutsTheLineBeforeIt)
{
  DebugLineSplitter splitter(10);
  const auto lines = split(splitter, std::string(8, 'y') + "\x02z\n");
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0].text, std::string(8, 'y'));  // never half an escape
  EXPECT_TRUE(lines[0].cut);
  EXPECT_EQ(splitter.stats().dropped_bytes, 2u);
}

TEST(EthernutDebugSplitter, EndlessGarbageWithoutALineEndNeverGrowsMemory)
{
  DebugLineSplitter splitter(64);
  std::string noise;
  for (int i = 0; i < 1 << 20; ++i)
  {
    noise.push_back(static_cast<char>((i * 37) & 0xFF) == '\r' || static_cast<char>((i * 37) & 0xFF) == '\n'
                        ? 'q'
                        : static_cast<char>((i * 37) & 0xFF));
  }
  size_t delivered = 0;
  const size_t chunk = 4096;
  for (size_t offset = 0; offset < noise.size(); offset += chunk)
  {
    delivered += split(splitter, noise.substr(offset, chunk)).size();
    ASSERT_LE(splitter.pending(), 64u);
  }
  EXPECT_EQ(delivered, 1u);  // one cut line, then everything dropped until a line end
  EXPECT_EQ(splitter.stats().cut_lines, 1u);
  EXPECT_GT(splitter.stats().dropped_bytes, (1u << 20) - 64u);
  EXPECT_EQ(texts(split(splitter, "\nback\n")), (std::vector<std::string>{"back"}));
}

TEST(EthernutDebugSplitter, TheUnfinishedLineIsDeliveredMarkedWhenTheLinkGoesAway)
{
  DebugLineSplitter splitter;
  EXPECT_TRUE(split(splitter, "3 GUI TCP res").empty());
  std::vector<DebugLine> lines;
  splitter.endOfStream([&](const DebugLine& line) { lines.push_back(line); });
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0].display(), "3 GUI TCP res [unterminated]");
  EXPECT_EQ(splitter.stats().unterminated, 1u);
  EXPECT_EQ(texts(split(splitter, "et 0\r\n")), (std::vector<std::string>{"et 0"}));  // not glued
  lines.clear();
  splitter.endOfStream([&](const DebugLine& line) { lines.push_back(line); });
  EXPECT_TRUE(lines.empty());
}

namespace
{
// What the channel delivered, waited on with a deadline (no sleeps).
struct Received
{
  std::mutex mutex;
  std::condition_variable changed;
  std::vector<std::string> lines;
  std::vector<LinkState> states;

  template <class Condition>
  bool waitFor(Condition condition)
  {
    std::unique_lock<std::mutex> lock(mutex);
    return changed.wait_for(lock, std::chrono::seconds(10), [&] { return condition(); });
  }
};

DebugChannelSettings ptySettings(const std::string& path)
{
  SerialSettings serial;
  serial.device = path;
  DebugChannelSettings settings;
  settings.link = LinkSettings::serialLine(serial, InputOnOpen::kKeep);
  settings.max_line = 32;
  settings.backoff = Backoff(Milliseconds(20), Milliseconds(100));
  return settings;
}
}  // namespace

TEST(EthernutDebugChannel, LinesArriveOverAPtyAndTheChannelSurvivesThePortVanishing)
{
  test::TempDir dir("ethernut_debug");
  const std::string path = dir.file("debug_port");
  auto pty = std::make_unique<PtyMaster>(path);
  Received got;  // before the channel: its thread reports to it until the channel is destroyed
  DebugChannel channel(ptySettings(path));
  channel.start(
      [&](const DebugLine& line)
      {
        std::lock_guard<std::mutex> lock(got.mutex);
        got.lines.push_back(line.display());
        got.changed.notify_all();
      },
      [&](LinkState state, const std::string&)
      {
        std::lock_guard<std::mutex> lock(got.mutex);
        got.states.push_back(state);
        got.changed.notify_all();
      });
  ASSERT_TRUE(got.waitFor([&] { return !got.states.empty() && got.states.back() == LinkState::kUp; }));
  pty->write(std::string("0 ucos DEBUG boot 0\r\n\x07noise\r\n") + std::string(50, 'z') + "\r\n3 GUI TCP res");
  ASSERT_TRUE(got.waitFor([&] { return got.lines.size() >= 3; }));

  // The port vanishes mid-line (the adapter unplugged): the partial line comes out marked, the
  // link goes down, and the channel keeps trying.
  pty.reset();
  ASSERT_TRUE(got.waitFor([&] { return got.lines.size() >= 4 && got.states.back() != LinkState::kUp; }));
  {
    const DebugChannelStatus status = channel.status();
    EXPECT_NE(status.link, LinkState::kUp);
    EXPECT_EQ(status.counts.unterminated, 1u);
  }

  // It comes back at the same path: the channel reopens it and reads on, nothing glued together.
  pty = std::make_unique<PtyMaster>(path);
  ASSERT_TRUE(got.waitFor([&] { return got.states.back() == LinkState::kUp; }));
  pty->write(std::string("1 TCP GUI accept 2\r\n"));
  ASSERT_TRUE(got.waitFor([&] { return got.lines.size() >= 5; }));
  std::lock_guard<std::mutex> lock(got.mutex);
  EXPECT_EQ(got.lines, (std::vector<std::string>{"0 ucos DEBUG boot 0", "\\x07noise", std::string(32, 'z') + " [cut]",
                                                 "3 GUI TCP res [unterminated]", "1 TCP GUI accept 2"}));
  const DebugChannelStatus status = channel.status();
  EXPECT_EQ(status.link, LinkState::kUp);
  EXPECT_EQ(status.counts.lines, 5u);
  EXPECT_EQ(status.counts.cut_lines, 1u);
  EXPECT_EQ(status.counts.escaped_bytes, 1u);
  EXPECT_EQ(status.last_line, "1 TCP GUI accept 2");
  EXPECT_GE(status.reconnects, 1u);
  EXPECT_EQ(status.device, path + "@9600 8N1");
}

TEST(EthernutDebugChannel, AnInvalidPortIsRefusedAtConstruction)
{
  SerialSettings serial;
  serial.device = "tcp://nowhere";  // no port
  DebugChannelSettings settings;
  settings.link = LinkSettings::serialLine(serial, InputOnOpen::kKeep);
  EXPECT_THROW(DebugChannel{settings}, ConfigError);
}
