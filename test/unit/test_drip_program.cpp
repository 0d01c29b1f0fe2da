// Unit tests of the program side of drip-feed: line reading with any line end, the character
// check (with line numbers), modal-state tracking, restart points and the send plan. The programs
// are written by the tests themselves (small Fanuc-style mill programs).
// The manual behind each refusal (lowercase, DC codes in the text, a % inside the program) and the
// EOB patterns: the table in test/data/dnc_drip/README.md.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <fstream>
#include <string>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dnc/dnc_codes.h"
#include "cnc_bridge/dnc/drip_feed.h"
#include "cnc_bridge/dnc/nc_program.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::dnc;
using namespace cnc_bridge::test;

namespace
{
const char* kProgram =
    "%\n"
    "O1234 (RESTART TEST)\n"
    "N10 G21 G17 G90 G54\n"
    "N20 T3 M6\n"
    "N30 G43 H3 S2400 M3\n"
    "N40 M8\n"
    "N50 G0 X0 Y0 Z5.\n"
    "N60 G1 Z-1. F150.\n"
    "N70 X10.\n"
    "N80 G2 X20. Y10. R10.\n"
    "N90 G1 Y20. F300.\n"
    "N100 G91 X5.\n"
    "N110 G90 G55 T7 M6\n"
    "N120 S1800 M4\n"
    "N130 G1 X1. F80.\n"
    "N140 M5 M9\n"
    "N150 M30\n"
    "%\n";
}  // namespace

TEST(LineReader, SplitsOnLfCrAndCrLfAlike)
{
  TempDir dir("test_drip_program");
  const auto path = dir.write("ends.nc", "A\nB\r\nC\rD\n\nE");
  LineReader reader(path);
  std::string line;
  std::vector<std::string> lines;
  while (reader.next(line))
  {
    lines.push_back(line);
  }
  EXPECT_EQ((std::vector<std::string>{"A", "B", "C", "D", "", "E"}), lines);
  EXPECT_EQ(6u, reader.lineNumber());
}

TEST(LineReader, CrLfAcrossTheReadBufferBoundaryIsOneLineEnd)
{
  TempDir dir("test_drip_program");
  std::string content(64 * 1024 - 1, 'X');  // the CR is the last byte of the first 64 KiB read
  content += "\r\nY\n";
  const auto path = dir.write("boundary.nc", content);
  LineReader reader(path, 128 * 1024);
  std::string line;
  ASSERT_TRUE(reader.next(line));
  EXPECT_EQ(64u * 1024 - 1, line.size());
  ASSERT_TRUE(reader.next(line));
  EXPECT_EQ("Y", line);
  EXPECT_FALSE(reader.next(line));
}

TEST(LineReader, OverlongLineIsRejectedWithItsNumber)
{
  TempDir dir("test_drip_program");
  const auto path = dir.write("long.nc", "G0\n" + std::string(100, 'X') + "\n");
  LineReader reader(path, 50);
  std::string line;
  ASSERT_TRUE(reader.next(line));
  try
  {
    reader.next(line);
    FAIL() << "no error";
  }
  catch (const ConfigError& e)
  {
    EXPECT_NE(std::string(e.what()).find("line 2"), std::string::npos) << e.what();
  }
}

TEST(LineReader, MissingFileIsAConfigError)
{
  EXPECT_THROW(LineReader("/nonexistent/x.nc"), ConfigError);
}

TEST(CheckLine, ReportsLowercaseControlCodesAndNonAsciiWithColumns)
{
  std::vector<CharacterIssue> issues;
  checkLine("G1 x1.\x13\xC3\xA9", 7, CharacterRules{}, issues);
  ASSERT_EQ(4u, issues.size());
  EXPECT_EQ(7u, issues[0].line);
  EXPECT_EQ(4u, issues[0].column);
  EXPECT_EQ('x', issues[0].byte);
  EXPECT_NE(issues[1].describe().find("DC code"), std::string::npos);
  EXPECT_EQ(0xC3, issues[2].byte);
  CharacterRules eight_bit;
  eight_bit.reject_lowercase = false;
  issues.clear();
  checkLine("(tool 3)\tG0", 1, eight_bit, issues);
  EXPECT_TRUE(issues.empty());
}

TEST(ModalTracker, TracksEveryRestatedGroup)
{
  ModalTracker tracker;
  for (const char* line : {"N10 G20 G18 G91 G54.1 P7", "T12", "M06", "G43 H12", "S900 M04", "M07", "G00 X1",
                           "G01 Z-1 F12.5 (CUT f99)", "; G21 comment only"})
  {
    tracker.apply(line);
  }
  const ModalState& s = tracker.state();
  EXPECT_EQ("G20", s.units);
  EXPECT_EQ("G18", s.plane);
  EXPECT_EQ("G91", s.distance);
  EXPECT_EQ("G54.1 P7", s.work_offset);
  EXPECT_EQ("T12", s.tool);
  EXPECT_EQ("G43 H12", s.tool_length);
  EXPECT_EQ("S900", s.spindle_speed);
  EXPECT_EQ("M4", s.spindle);
  EXPECT_EQ("M7", s.coolant);
  EXPECT_EQ("G1", s.motion);
  EXPECT_EQ("F12.5", s.feed);
  EXPECT_EQ("N10", s.sequence);
}

TEST(ModalTracker, LatheStyleToolWithoutM6)
{
  ModalTracker tracker;
  tracker.apply("T0101");
  tracker.apply("G97 S500 M3");
  EXPECT_EQ("T0101\nS500 M3\n", tracker.restartPreamble(9).substr(tracker.restartPreamble(9).find('\n') + 1));
}

TEST(ScanProgram, FindsFramingAndRestartByLineWithModalPreamble)
{
  TempDir dir("test_drip_program");
  const auto path = dir.write("p.nc", kProgram);
  RestartPoint at_line;
  at_line.line = 11;  // N90, after the arc of N80
  const auto scan = scanProgram(path, CharacterRules{}, at_line, 1);
  EXPECT_TRUE(scan.starts_with_percent);
  EXPECT_TRUE(scan.ends_with_percent);
  EXPECT_EQ(18u, scan.lines);
  EXPECT_EQ(11u, scan.start_line);
  EXPECT_EQ(
      "(RESTART AT LINE 11)\n"
      "G21 G17 G90 G54\n"
      "T3 M6\n"
      "G43 H3\n"
      "S2400 M3\n"
      "M8\n"
      "G1 F150.\n",
      scan.computed_preamble);
  ASSERT_EQ(1u, scan.warnings.size());  // the arc was restated as G1
  // Lines 11..18 with a 1-byte EOB.
  EXPECT_EQ(std::string("N90 G1 Y20. F300.\nN100 G91 X5.\nN110 G90 G55 T7 M6\nN120 S1800 M4\nN130 G1 X1. F80.\n"
                        "N140 M5 M9\nN150 M30\n%\n")
                .size(),
            scan.body_bytes);
}

TEST(ScanProgram, RestartByBlockNumberIgnoresLeadingZeros)
{
  TempDir dir("test_drip_program");
  const auto path = dir.write("p.nc", kProgram);
  RestartPoint at_block;
  at_block.block = "N0130";
  const auto scan = scanProgram(path, CharacterRules{}, at_block, 2);
  EXPECT_EQ(15u, scan.start_line);
  EXPECT_EQ("G21 G17 G90 G55", scan.computed_preamble.substr(scan.computed_preamble.find('\n') + 1, 15));
  EXPECT_NE(scan.computed_preamble.find("T7 M6\n"), std::string::npos);
  EXPECT_NE(scan.computed_preamble.find("S1800 M4\n"), std::string::npos);
  EXPECT_NE(scan.computed_preamble.find("G1 F300.\n"), std::string::npos);
}

TEST(ScanProgram, RestartPointNotInTheFileIsAnError)
{
  TempDir dir("test_drip_program");
  const auto path = dir.write("p.nc", kProgram);
  RestartPoint missing;
  missing.block = "N9999";
  EXPECT_THROW(scanProgram(path, CharacterRules{}, missing, 1), ConfigError);
  RestartPoint past;
  past.line = 99;
  EXPECT_THROW(scanProgram(path, CharacterRules{}, past, 1), ConfigError);
}

TEST(ScanProgram, PercentInTheMiddleIsReported)
{
  TempDir dir("test_drip_program");
  const auto path = dir.write("p.nc", "%\nG0 X1\n%\nG0 X2\n%\n");
  const auto scan = scanProgram(path, CharacterRules{}, {}, 1);
  ASSERT_EQ(1u, scan.issue_count);
  EXPECT_EQ(3u, scan.issues[0].line);
  EXPECT_TRUE(scan.ends_with_percent);
}

TEST(PlanDrip, RefusesAProgramTheControlCannotTakeNamingTheLines)
{
  TempDir dir("test_drip_program");
  const auto path = dir.write("bad.nc", "%\nG0 X1\ng1 y2\nG0 X\xB0\n%\n");
  try
  {
    planDrip(path, DripOptions{});
    FAIL() << "no error";
  }
  catch (const ConfigError& e)
  {
    const std::string what = e.what();
    EXPECT_NE(what.find("line 3 column 1"), std::string::npos) << what;
    EXPECT_NE(what.find("line 4 column 5"), std::string::npos) << what;
    EXPECT_NE(what.find("nothing was sent"), std::string::npos) << what;
  }
}

TEST(PlanDrip, AddsFramingOnlyWhenMissingAndCountsEveryByte)
{
  TempDir dir("test_drip_program");
  DripOptions options;
  options.eob = parseEob("crlf");
  options.leader_length = 5;
  options.trailer_length = 3;
  options.dc_codes = true;
  const auto bare = planDrip(dir.write("bare.nc", "G0 X1\nG1 Y2\n\n"), options);
  EXPECT_TRUE(bare.send_leading_percent);
  EXPECT_TRUE(bare.send_trailing_percent);
  EXPECT_EQ(2u + 5 + 3 + 3 + 3 + 7 + 7, bare.total_bytes);
  const auto framed = planDrip(dir.write("framed.nc", kProgram), options);
  EXPECT_FALSE(framed.send_leading_percent);
  EXPECT_FALSE(framed.send_trailing_percent);
  RestartPoint restart;
  restart.line = 5;
  const auto restarted = planDrip(dir.write("framed2.nc", kProgram), options, restart, "G90\nT3 M6\n");
  EXPECT_TRUE(restarted.send_leading_percent);  // the file's '%' was skipped
  EXPECT_EQ("G90\nT3 M6\n", restarted.preamble);
}

TEST(PlanDrip, ChecksAnEditedPreambleToo)
{
  TempDir dir("test_drip_program");
  RestartPoint restart;
  restart.line = 3;
  EXPECT_THROW(planDrip(dir.write("p.nc", kProgram), DripOptions{}, restart, "g90\n"), ConfigError);
}

// The one preamble check (~plan_drip and every feed): lines as the feed sends them.
TEST(PlanDrip, APreambleIsCheckedAsItIsSent)
{
  EXPECT_TRUE(checkPreamble("G21 G90 G54\r\n\r\nT4 M6\r\n", CharacterRules{}).empty());  // CR LF, a blank line
  const auto issues = checkPreamble("G90\n\n  \nt4 M6\n", CharacterRules{});
  ASSERT_EQ(1u, issues.size());
  EXPECT_EQ(2u, issues[0].line);  // the second line sent
  EXPECT_EQ(1u, issues[0].column);
  TempDir dir("test_drip_program");
  RestartPoint restart;
  restart.line = 3;
  const auto plan = planDrip(dir.write("p.nc", kProgram), DripOptions{}, restart, "G90\r\nT3 M6\r\n");
  EXPECT_EQ("G90\r\nT3 M6\r\n", plan.preamble);
}

TEST(Eob, NamesRoundTrip)
{
  for (const char* name : {"lf", "cr", "crlf", "lfcr", "lfcrcr"})
  {
    EXPECT_EQ(name, eobName(parseEob(name)));
  }
  EXPECT_THROW(parseEob("crcr"), ConfigError);
  EXPECT_EQ(0x93, withEvenParity(kDc3));
  EXPECT_EQ(0x11, withEvenParity(kDc1));
  EXPECT_EQ(kDc3, maskParity(0x93));
}
