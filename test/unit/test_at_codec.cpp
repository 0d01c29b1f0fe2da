// The '@'-protocol codec: every message of docs/protocols/at_protocol.md in both
// directions, byte-exact against the ESPRIT paper's own examples ("S150@", "JX@", "F150@", "T1 34@",
// "45334 34623 54934"), stream reassembly over split and merged reads, and malformed input.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "cnc_bridge/at_protocol/codec.h"
#include "cnc_bridge/common/error.h"

using namespace cnc_bridge;
using namespace cnc_bridge::at_protocol;

namespace
{
struct CommandCase
{
  Command command;
  std::string wire;
};

std::vector<CommandCase> commandCases()
{
  return {
      {AutoMode{}, "A@"},
      {JogMode{Axis::kX}, "JX@"},  // the ESPRIT paper: "JX@" for jog mode in X
      {JogMode{Axis::kY}, "JY@"},
      {JogMode{Axis::kZ}, "JZ@"},
      {Machining{true}, "M1@"},
      {Machining{false}, "M0@"},
      {StartOperation{true}, "P1@"},
      {StartOperation{false}, "P0@"},
      {Spindle{150}, "S150@"},  // paper's example
      {Spindle{0}, "S0@"},
      {Spindle{255}, "S255@"},
      {JogFeed{150}, "F150@"},        // paper's example
      {ToolChange{1, 34}, "T1 34@"},  // paper's example
      {Home{}, "H@"},
      {Setpoint{{12, -255, 0}, {3400, -5, 0}}, "12 3400 -255 -5 0 0@"},
      {Setpoint{{255, 0, -1}, {2147483647, -2147483647 - 1, 7}}, "255 2147483647 0 -2147483648 -1 7@"},
      {EndOperation{}, "#@"},
  };
}
}  // namespace

TEST(AtCodec, EveryCommandEncodesToThePapersText)
{
  for (const auto& c : commandCases())
  {
    EXPECT_EQ(encode(c.command), c.wire);
  }
}

TEST(AtCodec, EveryCommandDecodesBack)
{
  for (const auto& c : commandCases())
  {
    const std::string body = c.wire.substr(0, c.wire.size() - 1);
    const Command decoded = decodeCommand(body);
    EXPECT_EQ(decoded.index(), c.command.index()) << c.wire;
    EXPECT_EQ(encode(decoded), c.wire);
  }
}

TEST(AtCodec, DecodedValuesAreTheFieldsSent)
{
  const auto setpoint = std::get<Setpoint>(decodeCommand("-3 -1000  4 2000\t0 5"));
  EXPECT_EQ(setpoint.feed, (std::array<int, 3>{-3, 4, 0}));
  EXPECT_EQ(setpoint.position, (std::array<int32_t, 3>{-1000, 2000, 5}));
  const auto tool = std::get<ToolChange>(decodeCommand("T12 80"));
  EXPECT_EQ(tool.tool, 12);
  EXPECT_EQ(tool.length_mm, 80);
  EXPECT_EQ(std::get<JogMode>(decodeCommand("Jz")).axis, Axis::kZ);
  EXPECT_TRUE(std::get<StartOperation>(decodeCommand("P1")).coolant);
  EXPECT_FALSE(std::get<Machining>(decodeCommand("M0")).start);
}

TEST(AtCodec, OutOfRangeValuesNeverLeave)
{
  EXPECT_THROW(encode(Spindle{256}), ProtocolError);
  EXPECT_THROW(encode(Spindle{-1}), ProtocolError);  // clockwise only (step 8)
  EXPECT_THROW(encode(JogFeed{300}), ProtocolError);
  EXPECT_THROW(encode(Setpoint{{256, 0, 0}, {0, 0, 0}}), ProtocolError);
  EXPECT_THROW(encode(Setpoint{{0, 0, -256}, {0, 0, 0}}), ProtocolError);
  EXPECT_THROW(encode(ToolChange{-1, 10}), ProtocolError);
  EXPECT_THROW(encode(ToolChange{1, -10}), ProtocolError);
}

// Exact or refused: NaN, infinities, huge and negative values, lengths that are not whole
// millimetres are refused with the reason, never wrapped, clamped or zeroed.
TEST(AtCodec, ValuesAreScaledOrRefusedNeverWrapped)
{
  EXPECT_EQ(scaledValue(0.0, 24000.0, "spindle"), 0);
  EXPECT_EQ(scaledValue(24000.0, 24000.0, "spindle"), 255);
  EXPECT_EQ(scaledValue(12000.0, 24000.0, "spindle"), 128);
  for (const double bad : {std::nan(""), HUGE_VAL, -HUGE_VAL, 1e300, -1.0, 24000.001, 2147483648.0})
  {
    EXPECT_THROW(scaledValue(bad, 24000.0, "spindle"), ProtocolError) << bad;
  }
  try
  {
    scaledValue(1e300, 24000.0, "spindle speed");
    FAIL() << "1e300 was scaled";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_EQ(std::string(e.what()), "spindle speed 1.0000000000000001e+300 is outside 0..24000");
  }
  EXPECT_EQ(toolChangeFor(3, 0.05).length_mm, 50);
  EXPECT_EQ(toolChangeFor(3, 0.05).tool, 3);
  EXPECT_EQ(toolChangeFor(9999, 10.0).length_mm, 10000);
  for (const double bad : {std::nan(""), HUGE_VAL, -HUGE_VAL, 1e300, -0.001, 1e-7, 0.0505, 10.001, 2147483.648})
  {
    EXPECT_THROW(toolChangeFor(1, bad), ProtocolError) << bad;
  }
  EXPECT_THROW(toolChangeFor(-1, 0.05), ProtocolError);
  EXPECT_THROW(toolChangeFor(2147483648LL, 0.05), ProtocolError);
  try
  {
    toolChangeFor(1, 0.0505);
    FAIL() << "0.0505 m was rounded";
  }
  catch (const ProtocolError& e)
  {
    EXPECT_EQ(std::string(e.what()),
              "'@'-protocol: tool length 0.050500000000000003 m is not a whole millimetre (the "
              "tool change carries whole millimetres)");
  }
}

TEST(AtCodec, MalformedCommandsAreRefusedWithTheReason)
{
  const std::vector<std::string> bad = {"",
                                        "Q",
                                        "A1",
                                        "JW",
                                        "JXY",
                                        "M2",
                                        "M",
                                        "P",
                                        "S",
                                        "S-1",
                                        "S256",
                                        "S12x",
                                        "F1000",
                                        "T1",
                                        "T1 2 3",
                                        "Tx 3",
                                        "1 2 3 4 5",
                                        "1 2 3 4 5 6 7",
                                        "256 0 0 0 0 0",
                                        "0 0 0 0 0 2147483648",
                                        "1 2 3 4 5 x",
                                        "#1",
                                        "H H",
                                        "--1 0 0 0 0 0"};
  for (const auto& message : bad)
  {
    EXPECT_THROW(decodeCommand(message), ProtocolError) << message;
  }
  try
  {
    decodeCommand("S300");
    FAIL();
  }
  catch (const ProtocolError& e)
  {
    EXPECT_NE(std::string(e.what()).find("spindle speed"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("0..255"), std::string::npos) << e.what();
  }
}

TEST(AtCodec, ReassemblerJoinsMessagesSplitAcrossReads)
{
  const std::string stream = "M1@P1@S150@12 3400 -5 100 0 0@13 3413 -5 95 0 0@#@M0@";
  // Every possible split point, and one byte at a time.
  for (size_t cut = 0; cut <= stream.size(); ++cut)
  {
    CommandReassembler reassembler;
    auto first = reassembler.feed(stream.substr(0, cut));
    auto second = reassembler.feed(stream.substr(cut));
    first.messages.insert(first.messages.end(), second.messages.begin(), second.messages.end());
    ASSERT_EQ(first.messages.size(), 7u) << "cut at " << cut;
    EXPECT_EQ(first.messages[3], "12 3400 -5 100 0 0");
    EXPECT_TRUE(first.errors.empty() && second.errors.empty());
    EXPECT_EQ(reassembler.pending(), 0u);
  }
  CommandReassembler bytewise;
  std::vector<std::string> all;
  for (char c : stream)
  {
    for (auto& m : bytewise.feed(std::string(1, c)).messages)
    {
      all.push_back(m);
    }
  }
  EXPECT_EQ(all.size(), 7u);
  EXPECT_EQ(all.back(), "M0");
}

TEST(AtCodec, ReassemblerSplitsMergedReadsAndKeepsTheTail)
{
  CommandReassembler reassembler;
  const auto result = reassembler.feed("A@\r\nJX@ F20@H");
  ASSERT_EQ(result.messages.size(), 3u);
  EXPECT_EQ(result.messages[0], "A");
  EXPECT_EQ(result.messages[1], "JX");  // CR LF of a terminal dropped
  EXPECT_EQ(result.messages[2], "F20");
  EXPECT_EQ(reassembler.pending(), 1u);
  const auto rest = reassembler.feed("@");
  ASSERT_EQ(rest.messages.size(), 1u);
  EXPECT_EQ(rest.messages[0], "H");
}

TEST(AtCodec, OversizeMessageIsReportedOnceAndTheNextOneSurvives)
{
  CommandReassembler reassembler;
  const std::string garbage(1000, '7');
  auto result = reassembler.feed(garbage);
  EXPECT_EQ(result.errors.size(), 1u);
  EXPECT_TRUE(result.messages.empty());
  result = reassembler.feed(garbage + "@A@");
  EXPECT_TRUE(result.errors.empty());
  ASSERT_EQ(result.messages.size(), 1u);
  EXPECT_EQ(result.messages[0], "A");
}

TEST(AtCodec, EveryReportEncodesAndParses)
{
  const std::vector<std::pair<Report, std::string>> cases = {
      {EStopReport{true}, "E1\n"},
      {EStopReport{false}, "E0\n"},
      {AutoModeReport{}, "A\n"},
      {JogModeReport{Axis::kX}, "JX\n"},
      {JogModeReport{Axis::kY}, "JY\n"},
      {JogModeReport{Axis::kZ}, "JZ\n"},
      {HomeReport{}, "H\n"},
      {PositionReport{{45334, 34623, 54934}}, "45334 34623 54934\n"},  // paper's example
      {PositionReport{{-1, 0, -2147483647 - 1}}, "-1 0 -2147483648\n"},
  };
  for (const auto& [report, wire] : cases)
  {
    EXPECT_EQ(encode(report), wire);
    const Report parsed = parseReport(wire.substr(0, wire.size() - 1));
    EXPECT_EQ(parsed.index(), report.index()) << wire;
    EXPECT_EQ(encode(parsed), wire);
  }
  EXPECT_EQ(std::get<PositionReport>(parseReport("  1\t-2   3 ")).position, (std::array<int32_t, 3>{1, -2, 3}));
  EXPECT_TRUE(std::get<EStopReport>(parseReport("E1\r")).active);
}

TEST(AtCodec, MalformedReportsAreRefused)
{
  for (const std::string line : {"", "E", "E2", "E10", "JQ", "J", "JXX", "HH", "1 2", "1 2 3 4", "1 2 x",
                                 "99999999999 0 0", "A1", "\x01\x02", "- 1 2"})
  {
    EXPECT_THROW(parseReport(line), ProtocolError) << line;
  }
}

TEST(AtCodec, LineReassemblerAcceptsLfCrAndCrLf)
{
  LineReassembler lines;
  auto result = lines.feed("E1\r\nA\n\nJX\r1 2");
  ASSERT_EQ(result.messages.size(), 3u);
  EXPECT_EQ(result.messages[2], "JX");
  result = lines.feed(" 3\r\n");
  ASSERT_EQ(result.messages.size(), 1u);
  EXPECT_EQ(std::get<PositionReport>(parseReport(result.messages[0])).position[2], 3);
  result = lines.feed(std::string(500, 'x') + "\nH\n");
  EXPECT_EQ(result.errors.size(), 1u);
  ASSERT_EQ(result.messages.size(), 1u);
  EXPECT_EQ(result.messages[0], "H");
}
