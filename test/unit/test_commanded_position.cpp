// Unit tests of dnc::CommandedPosition, the commanded position of a drip-feed: block ends in G90
// and G91, G20 inches to metres, arcs, canned cycles, lines without motion, G53/G28/M98 leaving
// the program's frame, G92, refused and garbage lines (never a throw, never a move), and bytes
// split anywhere with every end-of-block pattern. The expected values are worked out by hand from
// the blocks (metres = program mm / 1000, inches * 0.0254).
#include <gtest/gtest.h>

#include <string>

#include "cnc_bridge/dnc/commanded_position.h"

using cnc_bridge::dnc::CommandedPosition;

namespace
{
constexpr double kTol = 1e-12;

void expectAt(const CommandedPosition& p, double x, double y, double z)
{
  ASSERT_TRUE(p.known());
  EXPECT_NEAR(x, p.metres().x, kTol);
  EXPECT_NEAR(y, p.metres().y, kTol);
  EXPECT_NEAR(z, p.metres().z, kTol);
}

CommandedPosition fedWith(std::initializer_list<const char*> lines)
{
  CommandedPosition p;
  for (const char* line : lines)
    p.feedLine(line);
  return p;
}
}  // namespace

TEST(CommandedPosition, NothingIsKnownBeforeTheFirstMotionBlock)
{
  CommandedPosition p;
  EXPECT_FALSE(p.known());
  for (const char* line : {"%", "O1234 (SETUP)", "N1 G21 G17 G90 G54", "N2 T4 M6", "N3 S4000 M3", "N4 M8"})
  {
    p.feedLine(line);
    EXPECT_FALSE(p.known()) << line;
  }
  EXPECT_EQ(0u, p.motionBlocks());
  EXPECT_EQ(0u, p.refused());
  p.feedLine("N5 G0 X10. Y-20. Z5.");
  expectAt(p, 0.010, -0.020, 0.005);
  EXPECT_EQ(1u, p.motionBlocks());
}

TEST(CommandedPosition, AnAxisIsKnownOnlyOnceTheProgramSetsItAbsolutely)
{
  CommandedPosition p = fedWith({"G90 G0 X1. Y2."});
  EXPECT_FALSE(p.known());  // Z not yet named: the tool's Z is where the operator left it
  p.feedLine("G91 G0 Z-5.");
  EXPECT_FALSE(p.known());  // incremental from an unknown Z is unknown
  p.feedLine("G90 G0 Z25.");
  expectAt(p, 0.001, 0.002, 0.025);
}

TEST(CommandedPosition, ABlockToWhereTheParserStartsIsAMotionBlockToo)
{
  // The parser starts at 0, 0, 0 and has no move for a block to there; the control's tool, coming
  // from wherever the operator left it, does move.
  CommandedPosition p = fedWith({"G90 G0 X0. Y0. Z0."});
  expectAt(p, 0.0, 0.0, 0.0);
  EXPECT_EQ(1u, p.motionBlocks());
  CommandedPosition g92 = fedWith({"G90 G0 X1. Y2. Z3.", "G92 X0. Y0. Z0."});
  EXPECT_EQ(1u, g92.motionBlocks());  // G92 sets numbers: nothing moved
  expectAt(g92, 0.001, 0.002, 0.003);
}

TEST(CommandedPosition, IncrementalBlocksAddToAKnownPosition)
{
  CommandedPosition p = fedWith({"G90 G0 X10. Y10. Z10.", "G91 G1 X5. F100.", "Y-2.5 Z-1."});
  expectAt(p, 0.015, 0.0075, 0.009);
  p.feedLine("G90 X0.");
  expectAt(p, 0.0, 0.0075, 0.009);
}

TEST(CommandedPosition, InchProgramsAreConvertedToMetres)
{
  CommandedPosition p = fedWith({"G20 G90", "G0 X1. Y-2. Z0.5"});
  expectAt(p, 0.0254, -0.0508, 0.0127);
  p.feedLine("G91 G1 X0.1 F10.");
  expectAt(p, 0.02794, -0.0508, 0.0127);
  p.feedLine("G21 G90 G1 X10.");  // back to millimetres
  expectAt(p, 0.010, -0.0508, 0.0127);
}

TEST(CommandedPosition, AnArcEndsAtItsEndPoint)
{
  // A half circle of radius 10 mm from (10, 0) to (-10, 0) round the origin, then a helix by R.
  CommandedPosition p = fedWith({"G90 G17 G0 X10. Y0. Z-1.", "G3 X-10. Y0. I-10. J0. F300."});
  expectAt(p, -0.010, 0.0, -0.001);
  p.feedLine("G2 X0. Y10. Z-2. R10.");
  expectAt(p, 0.0, 0.010, -0.002);
  p.feedLine("G91 G3 X0. Y-20. J-10.");  // incremental end point: back through the left half
  expectAt(p, 0.0, -0.010, -0.002);
}

TEST(CommandedPosition, LinesWithoutMotionLeaveThePositionAlone)
{
  CommandedPosition p = fedWith({"G90 G0 X1. Y2. Z3."});
  const uint64_t blocks = p.motionBlocks();
  for (const char* line : {"M5", "(A COMMENT X99. Y99.)", "", "S1200 M3", "G4 P1.", "T2 M6", "G91", "%", "M30"})
  {
    p.feedLine(line);
    expectAt(p, 0.001, 0.002, 0.003);
  }
  EXPECT_EQ(blocks, p.motionBlocks());
}

TEST(CommandedPosition, ACannedCycleEndsAtItsReturnLevel)
{
  CommandedPosition p = fedWith({"G90 G0 X0. Y0. Z20.", "G99 G81 X5. Y6. Z-3. R2. F100."});
  expectAt(p, 0.005, 0.006, 0.002);  // G99: the R plane, not the bottom of the hole
  p.feedLine("G98 X7.");
  expectAt(p, 0.007, 0.006, 0.020);  // G98: the initial level (above R)
  p.feedLine("G80");
  CommandedPosition unknown_z = fedWith({"G90 G0 X0. Y0.", "G98 G81 X5. Y6. Z-3. R2. F100."});
  EXPECT_FALSE(unknown_z.known());  // G98 returns to a Z that was never programmed
}

TEST(CommandedPosition, MachineCoordinatesAndReferenceReturnsLeaveTheProgramFrame)
{
  CommandedPosition p = fedWith({"G90 G0 X1. Y2. Z3.", "G53 G0 Z0."});
  EXPECT_FALSE(p.known());  // machine Z0: where that is in the program's frame is the control's
  p.feedLine("G0 Z10.");
  expectAt(p, 0.001, 0.002, 0.010);
  p.feedLine("G28 G91 Z0.");  // the usual Haas tool-change retract
  EXPECT_FALSE(p.known());
  p.feedLine("G90 G0 Z5.");
  expectAt(p, 0.001, 0.002, 0.005);
  p.feedLine("G28");  // Haas: every axis home
  EXPECT_FALSE(p.known());
  p.feedLine("G0 Z1.");
  EXPECT_FALSE(p.known());  // X and Y are still at home
  p.feedLine("X0. Y0.");
  expectAt(p, 0.0, 0.0, 0.001);
}

TEST(CommandedPosition, ASubprogramOnTheControlMakesEveryAxisUnknown)
{
  CommandedPosition p = fedWith({"G90 G0 X1. Y2. Z3.", "M98 P1000"});
  EXPECT_FALSE(p.known());
}

TEST(CommandedPosition, G92FromAnUnknownPositionLosesTheFrameUntilG921)
{
  CommandedPosition known = fedWith({"G90 G0 X10. Y10. Z10.", "G92 X0. Y0.", "G1 X5. F100."});
  expectAt(known, 0.015, 0.010, 0.010);  // G92 shifts undone: the frame the program started in
  CommandedPosition lost = fedWith({"G90 G0 Y10. Z10.", "G92 X0.", "G1 X5. F100."});
  EXPECT_FALSE(lost.known());  // X was re-zeroed from a place the host never saw
  lost.feedLine("G92.1");
  lost.feedLine("G0 X3.");
  expectAt(lost, 0.003, 0.010, 0.010);
}

TEST(CommandedPosition, GarbageNeverThrowsNorMovesThePosition)
{
  CommandedPosition p = fedWith({"G90 G0 X1. Y2. Z3."});
  for (const char* garbage : {"hello world!", "\x7f\x80\xff ???", "((((", "N", "G21 ) junk (", "M123 Q"})
  {
    EXPECT_NO_THROW(p.feedLine(garbage)) << garbage;
    expectAt(p, 0.001, 0.002, 0.003);
  }
  EXPECT_GE(p.refused(), 3u);
  EXPECT_FALSE(p.lastRefusal().empty());
}

TEST(CommandedPosition, ARefusedBlockForgetsTheAxesItNamesAndKeepsItsModes)
{
  CommandedPosition p = fedWith({"G90 G0 X1. Y2. Z3."});
  p.feedLine("G1 X#100 F100.");  // a macro value: X went somewhere the host cannot tell
  EXPECT_EQ(1u, p.refused());
  EXPECT_FALSE(p.known());
  p.feedLine("X4.");
  expectAt(p, 0.004, 0.002, 0.003);
  p.feedLine("G20 G91 G1 Y#1");  // refused, but inch and incremental still hold at the control
  EXPECT_FALSE(p.known());
  p.feedLine("G90 Y1.");
  expectAt(p, 0.004, 0.0254, 0.003);
  p.feedLine("G65 P9010 A1.");  // a macro call: anything may have moved
  EXPECT_FALSE(p.known());
}

TEST(CommandedPosition, ABlockDeleteLineForgetsWhatItMoves)
{
  CommandedPosition p = fedWith({"G90 G0 X1. Y2. Z3.", "/G0 Z50."});
  EXPECT_FALSE(p.known());  // the operator's switch decides whether the control ran it
  p.feedLine("G0 Z4.");
  expectAt(p, 0.001, 0.002, 0.004);
}

TEST(CommandedPosition, BytesSplitAnywhereMakeTheSameBlocks)
{
  for (const std::string eob : {"\n", "\r", "\r\n", "\n\r", "\n\r\r"})
  {
    const std::string wire = std::string("\x12%") + eob + "G90 G0 X1. Y2. Z3." + eob + "G1 X-4.5 F100." + eob + "%" +
                             eob + std::string(3, '\0') + "\x14";
    for (size_t split = 0; split <= wire.size(); ++split)
    {
      CommandedPosition p;
      p.feedBytes(wire.substr(0, split));
      p.feedBytes(wire.substr(split));
      SCOPED_TRACE("eob " + std::to_string(eob.size()) + " bytes, split at " + std::to_string(split));
      expectAt(p, -0.0045, 0.002, 0.003);
      EXPECT_EQ(2u, p.motionBlocks());
      EXPECT_EQ(0u, p.refused());
    }
  }
  // A line's first half is not a block: nothing is known until its end of block arrives.
  CommandedPosition p;
  p.feedBytes("G90 G0 X1. Y2.");
  EXPECT_FALSE(p.known());
  p.feedBytes(" Z3.\r");
  expectAt(p, 0.001, 0.002, 0.003);
}

TEST(CommandedPosition, AnOverlongLineIsRefusedAndForgetsEverything)
{
  CommandedPosition p;
  p.feedBytes("G90 G0 X1. Y2. Z3.\n");
  p.feedBytes("G1 X2." + std::string(10000, ' ') + "\n");
  EXPECT_FALSE(p.known());
  EXPECT_EQ(1u, p.refused());
  p.feedBytes("G0 X1. Y2. Z3.\n");
  expectAt(p, 0.001, 0.002, 0.003);
}

TEST(CommandedPosition, ResetForgetsTheFeed)
{
  CommandedPosition p = fedWith({"G20 G90 G0 X1. Y2. Z3."});
  p.feedBytes("G0 X5");  // an unfinished line is dropped too
  p.reset();
  EXPECT_FALSE(p.known());
  EXPECT_EQ(0u, p.lines());
  p.feedLine("G0 X1. Y2. Z3.");
  expectAt(p, 0.001, 0.002, 0.003);  // millimetres again: G20 belonged to the last feed
}
