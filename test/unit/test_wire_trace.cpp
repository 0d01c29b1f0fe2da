// Wire traces (cnc_bridge/transport/wire_trace.h): a traced line writes what passes both ways in a
// sniffer's layout, bounded; the reader takes back its own traces and a sniffer's dump (the Haas
// capture of test/data/xmodem/), and refuses what is not a trace, naming the line; the replay plays
// the far side on a pty and notices every way the program under test can differ.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/transport/serial_line.h"
#include "cnc_bridge/transport/wire_trace.h"
#include "temp_dir.h"
#include "testing/pty.h"

using namespace cnc_bridge;
using cnc_bridge::test::readFile;
using cnc_bridge::test::TempDir;

namespace
{
std::vector<uint8_t> bytesOf(const std::string& text)
{
  return std::vector<uint8_t>(text.begin(), text.end());
}

std::vector<TraceEntry> parseText(const std::string& text)
{
  std::istringstream in(text);
  return parseWireTrace(in, "trace.txt");
}

SerialSettings ptyLine(const PtyMaster& pty)
{
  SerialSettings settings;
  settings.device = pty.slavePath();
  settings.baud = 115200;
  return settings;
}

std::string onlyFileIn(const std::string& dir)
{
  std::vector<std::string> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir))
  {
    files.push_back(entry.path().string());
  }
  EXPECT_EQ(files.size(), 1u) << "trace files in " << dir;
  return files.empty() ? "" : files.front();
}

std::vector<TraceEntry> parseFile(const std::string& path)
{
  std::ifstream in(path);
  return parseWireTrace(in, path);
}
}  // namespace

TEST(WireTrace, ATracedLineRecordsBothDirectionsInOrderWithEveryByteValue)
{
  TempDir dir("test_wire_trace");
  PtyMaster machine;
  SerialSettings settings = ptyLine(machine);
  settings.wire_trace.dir = dir.path;
  std::vector<uint8_t> every_value(256);
  for (size_t i = 0; i < every_value.size(); ++i)
  {
    every_value[i] = static_cast<uint8_t>(i);
  }
  {
    auto line = openSerialLine(settings);
    line->write(every_value);
    line->drain();
    std::vector<uint8_t> seen(256);
    ASSERT_EQ(machine.readExactly(seen.data(), seen.size(), Milliseconds(2000)), 256u);
    machine.write(std::string("\x06"));
    machine.drain();
    uint8_t ack = 0;
    ASSERT_EQ(line->readExactly(&ack, 1, Milliseconds(2000)), 1u);
    line->close();
  }
  const std::string path = onlyFileIn(dir.path);
  const auto entries = parseFile(path);
  ASSERT_EQ(entries.size(), 2u) << readFile(path);
  EXPECT_EQ(entries[0].direction, TraceDirection::kWritten);
  EXPECT_EQ(entries[0].bytes, every_value);
  EXPECT_EQ(entries[1].direction, TraceDirection::kRead);
  EXPECT_EQ(entries[1].bytes, bytesOf("\x06"));
  EXPECT_LE(entries[0].time, entries[1].time);
  // The sniffer's layout: the header names the link, the text column shows the printable bytes.
  const std::string text = readFile(path);
  EXPECT_NE(text.find("] Written data (" + machine.slavePath()), std::string::npos) << text;
  EXPECT_NE(text.find("    30 31 32 33 34 35 36 37 38 39 3a 3b 3c 3d 3e 3f   0123456789:;<=>?"), std::string::npos)
      << text;
  EXPECT_NE(text.find("link closed"), std::string::npos) << text;
}

TEST(WireTrace, AnUntracedLineWritesNoFile)
{
  TempDir dir("test_wire_trace");
  PtyMaster machine;
  auto line = openSerialLine(ptyLine(machine));
  line->write(std::string("N10G0X0\n"));
  EXPECT_EQ(dynamic_cast<TracingSerialLine*>(line.get()), nullptr);
  EXPECT_TRUE(std::filesystem::is_empty(dir.path));
}

TEST(WireTrace, ATraceStopsAtItsLimitAndSaysSoWhileTheLinkGoesOn)
{
  TempDir dir("test_wire_trace");
  PtyMaster machine;
  SerialSettings settings = ptyLine(machine);
  settings.wire_trace.dir = dir.path;
  settings.wire_trace.max_bytes = 100;
  auto line = openSerialLine(settings);
  const std::string block(60, 'X');
  line->write(block);  // 60: traced
  line->write(block);  // 120 > 100: not traced, the trace says so
  line->write(block);  // still carried, not traced
  line->drain();
  std::vector<uint8_t> seen(180);
  EXPECT_EQ(machine.readExactly(seen.data(), seen.size(), Milliseconds(2000)), 180u);
  const std::string path = onlyFileIn(dir.path);
  const auto entries = parseFile(path);
  ASSERT_EQ(entries.size(), 1u);
  EXPECT_EQ(entries[0].bytes.size(), 60u);
  EXPECT_NE(readFile(path).find("limit of 100 bytes is reached"), std::string::npos) << readFile(path);
}

TEST(WireTrace, AMissingFolderIsMade)
{
  TempDir dir("test_wire_trace");
  PtyMaster machine;
  SerialSettings settings = ptyLine(machine);
  settings.wire_trace.dir = dir.path + "/cell/traces";
  openSerialLine(settings)->write(std::string("%\n"));
  EXPECT_FALSE(onlyFileIn(dir.path + "/cell/traces").empty());
}

TEST(WireTrace, AFolderThatCannotBeMadeIsAClearErrorBeforeAnyByteMoves)
{
  TempDir dir("test_wire_trace");
  const std::string not_a_folder = dir.write("traces", "a file where the folder belongs");
  PtyMaster machine;
  SerialSettings settings = ptyLine(machine);
  settings.wire_trace.dir = not_a_folder;
  try
  {
    openSerialLine(settings);
    FAIL() << "opened a traced line whose trace cannot be written";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find(not_a_folder), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("writable"), std::string::npos) << e.what();
  }
  uint8_t byte = 0;
  EXPECT_EQ(machine.read(&byte, 1, Milliseconds(50)), 0u) << "the machine received a byte";
}

TEST(WireTrace, TheFileNameTellsTheLinkAndTheTime)
{
  const auto when = std::chrono::system_clock::from_time_t(1764316862);  // 2025-11-28 08:01:02 UTC
  EXPECT_EQ(wireTracePath("/tmp/t", "/dev/ttyUSB0", when), "/tmp/t/dev_ttyUSB0-20251128T080102.000000.trace");
  EXPECT_EQ(wireTracePath("/tmp/t", "rfc2217://10.0.0.5:2001", when),
            "/tmp/t/rfc2217___10.0.0.5_2001-20251128T080102.000000.trace");
}

TEST(WireTraceReader, ReadsASniffersDumpWithItsOwnTimes)
{
  const auto entries = parseText(
      "[30/10/2017 10:27:11] Written data (COM2)\t\n"
      "    15                                                .               \t\n"
      "[30/10/2017 10:27:21] Read data (COM2)\t\n"
      "    01 01 fe 0a 25 0a 4f 30 35 35 35 35 28 43 53 33   ..\xc3\xbe.%.O05555(CS3\t\n"
      "    39 30                                             90\t\n");
  ASSERT_EQ(entries.size(), 2u);
  EXPECT_EQ(entries[0].direction, TraceDirection::kWritten);
  EXPECT_EQ(entries[0].bytes, std::vector<uint8_t>{0x15});
  EXPECT_EQ(entries[1].direction, TraceDirection::kRead);
  EXPECT_EQ(entries[1].bytes.size(), 18u);
  EXPECT_EQ(entries[1].bytes[2], 0xfe);
  EXPECT_DOUBLE_EQ(entries[1].time - entries[0].time, 10.0);
}

TEST(WireTraceReader, TheHaasCaptureReadsAsTheBytesOfItsFixture)
{
  const auto entries = parseFile(XMODEM_TEST_DATA "/haas_capture_cnc_to_pc.trace");
  ASSERT_EQ(entries.size(), 20u);
  size_t blocks = 0;
  for (const auto& entry : entries)
  {
    if (entry.direction == TraceDirection::kRead && entry.bytes.size() == 132)
    {
      ++blocks;
      EXPECT_EQ(entry.bytes[0], 0x01);
      EXPECT_EQ(entry.bytes[1], blocks);
    }
  }
  EXPECT_EQ(blocks, 8u);
}

TEST(WireTraceReader, RefusesWhatIsNotATraceNamingTheLine)
{
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"    01 02\n", "line 1: bytes outside an entry"},
      {"[yesterday] Written data (COM2)\n", "line 1: no time in brackets"},
      {"[2026-11-28 08:01:02.5] Sent data (COM2)\n", "line 1: neither"},
      {"[2026-11-28 08:01:02.5] Read data (x)\n    01 zz\n", "line 2: 'zz' is not a hex byte"},
      {"[2026-11-28 08:01:02.5] Read data (x)\n    0102\n", "line 2: '0102' is not a hex byte"},
      {"garbage\x01\xff\n", "line 1"},
  };
  for (const auto& [text, wanted] : bad)
  {
    try
    {
      parseText(text);
      ADD_FAILURE() << "took as a trace: " << text;
    }
    catch (const ConfigError& e)
    {
      EXPECT_NE(std::string(e.what()).find("trace.txt " + wanted), std::string::npos) << e.what();
    }
  }
}

namespace
{
/// The program under test in a thread: answers each chunk the replay sends with \p answer.
class Responder
{
 public:
  Responder(const std::string& device, std::function<void(Transport&)> act)
  {
    SerialSettings settings;
    settings.device = device;
    settings.baud = 115200;
    line_ = openSerialLine(settings);
    thread_ = std::thread([this, act] { act(*line_); });
  }
  ~Responder() { thread_.join(); }

 private:
  std::unique_ptr<SerialLine> line_;
  std::thread thread_;
};

std::vector<TraceEntry> exchange()
{
  // The program writes "?Q100\r", the machine answers "S/N 12345\r\n", the program writes "?Q500\r".
  return {{TraceDirection::kWritten, 0.0, bytesOf("?Q100\r")},
          {TraceDirection::kRead, 0.05, bytesOf("S/N 12345\r\n")},
          {TraceDirection::kWritten, 0.1, bytesOf("?Q5")},
          {TraceDirection::kWritten, 0.1, bytesOf("00\r")}};
}

void readAnswer(Transport& line)
{
  std::vector<uint8_t> answer(11);
  line.readExactly(answer.data(), answer.size(), Milliseconds(5000));
}

TraceReplay::Options quick()
{
  TraceReplay::Options options;
  options.host_slack = Milliseconds(2000);
  options.quiet_after = Milliseconds(200);
  return options;
}

/// exchange() replayed against \p program, which runs on the other end of a pty.
ReplayResult replayAgainst(const std::function<void(Transport&)>& program)
{
  PtyMaster far_side;
  TraceReplay replay(exchange(), quick());
  Responder responder(far_side.slavePath(), program);
  return replay.run(far_side);
}
}  // namespace

TEST(TraceReplay, AProgramThatAnswersAsRecordedMatches)
{
  const ReplayResult result = replayAgainst(
      [](Transport& line)
      {
        line.write(std::string("?Q100\r"));
        readAnswer(line);
        line.write(std::string("?Q500\r"));  // in one piece where the trace has two: the same bytes
      });
  EXPECT_TRUE(result.matched) << result.message;
  EXPECT_EQ(result.bytes_sent, 11u);
  EXPECT_EQ(result.bytes_checked, 12u);
}

TEST(TraceReplay, AWrongByteIsADifferenceNamingTheEntryAndTheByte)
{
  const ReplayResult result = replayAgainst(
      [](Transport& line)
      {
        line.write(std::string("?Q100\r"));
        readAnswer(line);
        line.write(std::string("?Q600\r"));
      });
  EXPECT_FALSE(result.matched);
  EXPECT_NE(result.message.find("entry 3 of 3"), std::string::npos) << result.message;
  EXPECT_NE(result.message.find("sent 36 where the trace has 35 (byte 3 of 6)"), std::string::npos) << result.message;
}

TEST(TraceReplay, AProgramThatFallsSilentIsADifferenceAfterTheRecordedTimeAndTheSlack)
{
  const ReplayResult result = replayAgainst(
      [](Transport& line)
      {
        line.write(std::string("?Q100\r"));
        readAnswer(line);
      });
  EXPECT_FALSE(result.matched);
  EXPECT_NE(result.message.find("sent 0 of the 6 bytes the trace expects next (next: 3f)"), std::string::npos)
      << result.message;
}

TEST(TraceReplay, BytesAfterTheTracesEndAreADifference)
{
  const ReplayResult result = replayAgainst(
      [](Transport& line)
      {
        line.write(std::string("?Q100\r"));
        readAnswer(line);
        line.write(std::string("?Q500\r?Q104\r"));
      });
  EXPECT_FALSE(result.matched);
  EXPECT_NE(result.message.find("after the trace's end (first: 3f)"), std::string::npos) << result.message;
}

TEST(TraceReplay, TheFarSidesBytesKeepTheirRecordedPaceScaledBySpeed)
{
  PtyMaster far_side;
  std::vector<TraceEntry> slow = {{TraceDirection::kRead, 0.0, bytesOf("A")},
                                  {TraceDirection::kRead, 0.4, bytesOf("B")}};
  TraceReplay::Options options = quick();
  options.speed = 2.0;
  TraceReplay replay(slow, options);
  std::chrono::steady_clock::duration between{};
  {
    Responder program(far_side.slavePath(),
                      [&between](Transport& line)
                      {
                        uint8_t byte = 0;
                        line.readExactly(&byte, 1, Milliseconds(5000));
                        const auto first = std::chrono::steady_clock::now();
                        line.readExactly(&byte, 1, Milliseconds(5000));
                        between = std::chrono::steady_clock::now() - first;
                      });
    EXPECT_TRUE(replay.run(far_side).matched);
  }
  // 0.4 s recorded at twice the speed: at least 0.2 s apart (a lower bound: a loaded machine is late,
  // never early).
  EXPECT_GE(between, std::chrono::milliseconds(195));
}

TEST(TraceReplay, RefusesASpeedThatIsNoSpeed)
{
  TraceReplay::Options options;
  for (const double speed : {0.0, -1.0, std::nan(""), 1e300})
  {
    options.speed = speed;
    EXPECT_THROW(TraceReplay(exchange(), options), ConfigError) << speed;
  }
}
