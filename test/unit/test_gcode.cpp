// Unit tests of the G-code parser: OpenDNC's Haas program (inch, G18/G17 arcs) end to end, arc
// geometry (IJK and R, every plane, chord tolerance), modal state, and malformed input with line
// and column.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "cnc_bridge/gcode/gcode.h"

using namespace cnc_bridge::gcode;

namespace
{
constexpr double kInch = 25.4;

std::vector<Move> parseAll(const std::string& program, const ParserOptions& options = ParserOptions())
{
  std::istringstream in(program);
  std::vector<Move> moves;
  forEachMove(
      in, [&](const Move& m) { moves.push_back(m); }, options);
  return moves;
}

ParseError parseError(const std::string& program)
{
  try
  {
    parseAll(program);
  }
  catch (const ParseError& e)
  {
    return e;
  }
  ADD_FAILURE() << "no ParseError for: " << program;
  return ParseError(0, 0, "none");
}

void expectNear(const Vec3& a, const Vec3& b, double tol = 1e-9)
{
  EXPECT_NEAR(a.x, b.x, tol);
  EXPECT_NEAR(a.y, b.y, tol);
  EXPECT_NEAR(a.z, b.z, tol);
}

// Largest distance between the chords and the circle they approximate (centre c, in the plane
// given by axes u, v).
double maxChordDeviation(const std::vector<Move>& moves, double cu, double cv, double r, int u, int v)
{
  auto get = [](const Vec3& p, int a) { return a == 0 ? p.x : (a == 1 ? p.y : p.z); };
  double worst = 0;
  for (const Move& m : moves)
  {
    const double mu = (get(m.start, u) + get(m.end, u)) / 2, mv = (get(m.start, v) + get(m.end, v)) / 2;
    worst = std::max(worst, r - std::hypot(mu - cu, mv - cv));
    worst = std::max(worst, std::fabs(std::hypot(get(m.end, u) - cu, get(m.end, v) - cv) - r));
  }
  return worst;
}
}  // namespace

TEST(GcodeFixture, HaasProgramParsesWithArcEndpointsAndStaysInsideThePart)
{
  std::ifstream in(CNC_BRIDGE_FIXTURE_DIR "/haas_O05555.nc", std::ios::binary);
  ASSERT_TRUE(in.good());
  Reader reader(in);
  std::vector<Move> moves;
  Bounds cut;  // everything except the G53 machine-coordinate retracts
  int64_t program = -1;
  bool ended = false;
  int tool_changes = 0;
  std::map<int64_t, std::pair<Vec3, Vec3>> arcs;  // N -> (first chord start, last chord end)
  while (const Block* b = reader.nextBlock())
  {
    if (b->program_number >= 0)
    {
      program = b->program_number;
    }
    ended |= b->program_end;
    tool_changes += b->tool_change;
    for (const Move& m : b->moves)
    {
      moves.push_back(m);
      if (!m.machine_coordinates)
      {
        cut.add(m.end);  // the first start is the power-on origin, not part of the program
      }
      if (m.motion == Motion::kArcCw || m.motion == Motion::kArcCcw)
      {
        if (m.segment == 0)
        {
          arcs[m.block_number].first = m.start;
        }
        if (m.segment + 1 == m.segment_count)
        {
          arcs[m.block_number].second = m.end;
        }
      }
    }
  }
  EXPECT_EQ(program, 5555);
  EXPECT_TRUE(ended);
  EXPECT_EQ(tool_changes, 1);
  EXPECT_EQ(reader.parser().state().units, Units::kInches);
  EXPECT_EQ(reader.parser().state().tool, 1);  // T3 was selected but never changed in (no M06)
  ASSERT_FALSE(moves.empty());

  // Twelve arcs: N85 N100 N110 N120 N140 N155 N165 N175 N195 N210 N220 N230.
  EXPECT_EQ(arcs.size(), 12u);
  // N85 G18 G03 X5.475 Z-0.025 I-0.2 K0 from X5.675 Y0.3147 Z0.175.
  expectNear(arcs[85].first, {5.675 * kInch, 0.3147 * kInch, 0.175 * kInch});
  expectNear(arcs[85].second, {5.475 * kInch, 0.3147 * kInch, -0.025 * kInch});
  // N100 G17 G02 Y1.6103 I0 J0.6478 from X0 Y0.3147 Z-0.025 (a half circle on the X- side).
  expectNear(arcs[100].first, {0, 0.3147 * kInch, -0.025 * kInch});
  expectNear(arcs[100].second, {0, 1.6103 * kInch, -0.025 * kInch});
  expectNear(arcs[230].second, {-0.2 * kInch, 2.906 * kInch, 0.075 * kInch});

  // The N100 half circle bulges to X = -0.6478 in: clockwise from (0, 0.3147) about (0, 0.9625)
  // goes through the -X side.
  double min_x_n100 = 0;
  for (const Move& m : moves)
  {
    if (m.block_number == 100)
    {
      min_x_n100 = std::min(min_x_n100, m.end.x);
      EXPECT_EQ(m.motion, Motion::kArcCw);
      EXPECT_NEAR(m.feed_mm_per_min, 65 * kInch, 1e-9);
    }
  }
  EXPECT_NEAR(min_x_n100, -0.6478 * kInch, 0.011);

  // The preview stays inside the part's extent (plus the arcs' bulge and the retract heights).
  const double tol = 1e-6;
  EXPECT_GE(cut.min.x, -1.3 * kInch - tol);
  EXPECT_LE(cut.max.x, 5.675 * kInch + tol);
  EXPECT_GE(cut.min.y, 0.3147 * kInch - tol);
  EXPECT_LE(cut.max.y, 2.906 * kInch + tol);
  EXPECT_GE(cut.min.z, -0.125 * kInch - tol);
  EXPECT_LE(cut.max.z, 1.0 * kInch + tol);
  // G53 retract moves are flagged.
  EXPECT_TRUE(std::any_of(moves.begin(), moves.end(), [](const Move& m) { return m.machine_coordinates; }));
  // Moves chain: each starts where the previous ended.
  for (size_t k = 1; k < moves.size(); ++k)
  {
    expectNear(moves[k].start, moves[k - 1].end, 1e-9);
  }
}

TEST(GcodeParser, QcncPhrasingDefaultsToAbsoluteFeedMoves)
{
  std::ifstream in(CNC_BRIDGE_FIXTURE_DIR "/seed_hello.nc", std::ios::binary);
  std::vector<Move> moves;
  forEachMove(in, [&](const Move& m) { moves.push_back(m); });
  ASSERT_EQ(moves.size(), 7u);  // N10 from the origin moves only Z
  for (const Move& m : moves)
  {
    EXPECT_EQ(m.motion, Motion::kLinear);
  }
  expectNear(moves[0].end, {0, 0, 5});
  expectNear(moves[3].end, {10, 10, -1});
  EXPECT_EQ(moves[3].line, 6u);
  EXPECT_EQ(moves[3].block_number, 40);
}

TEST(GcodeParser, InchesAndIncrementalAreConverted)
{
  const auto moves = parseAll("G20 G91 G00 X1 Y-2\nG01 Z0.5 F10\nG21 G90 X10\n");
  ASSERT_EQ(moves.size(), 3u);
  expectNear(moves[0].end, {25.4, -50.8, 0});
  EXPECT_EQ(moves[0].motion, Motion::kRapid);
  expectNear(moves[1].end, {25.4, -50.8, 12.7});
  EXPECT_DOUBLE_EQ(moves[1].feed_mm_per_min, 254.0);
  expectNear(moves[2].end, {10, -50.8, 12.7});
  // A feed set under G20 stays what it was in mm/min after G21.
  EXPECT_DOUBLE_EQ(moves[2].feed_mm_per_min, 254.0);
}

TEST(GcodeParser, CommentsNumbersAndCase)
{
  Parser p;
  const Block& b = p.parseLine("n5 g1 x+1.5 (move y) y -.5 ; trailing Z9");
  EXPECT_EQ(b.block_number, 5);
  ASSERT_EQ(b.moves.size(), 1u);
  expectNear(b.moves[0].end, {1.5, -0.5, 0});
  EXPECT_TRUE(p.parseLine("(only a comment)").moves.empty());
  EXPECT_FALSE(p.parseLine("(only a comment)").has_words);
  EXPECT_TRUE(p.parseLine("%").tape_marker);
  EXPECT_EQ(p.parseLine("O1234 (NAME)").program_number, 1234);
  const Block& crlf = p.parseLine("X2\r");
  ASSERT_EQ(crlf.moves.size(), 1u);
  EXPECT_DOUBLE_EQ(crlf.moves[0].end.x, 2.0);
  EXPECT_EQ(p.lineCount(), 6u);
}

TEST(GcodeParser, SpindleToolCoolantAndMCodes)
{
  Parser p;
  p.parseLine("T7 M06");
  p.parseLine("S1200 M04 M08");
  const Block& b = p.parseLine("G1 X1 F100 M123");
  ASSERT_EQ(b.moves.size(), 1u);
  EXPECT_EQ(b.moves[0].tool, 7);
  EXPECT_EQ(b.moves[0].spindle, Spindle::kCounterClockwise);
  EXPECT_DOUBLE_EQ(b.moves[0].spindle_rpm, 1200);
  EXPECT_TRUE(b.moves[0].coolant);
  ASSERT_EQ(b.m_count, 1u);
  EXPECT_EQ(b.m_codes[0], 123);
  p.parseLine("M05 M09");
  EXPECT_EQ(p.state().spindle, Spindle::kOff);
  EXPECT_FALSE(p.state().coolant);
  EXPECT_TRUE(p.parseLine("M30").program_end);
  EXPECT_TRUE(p.parseLine("M01").program_stop);
  EXPECT_DOUBLE_EQ(p.parseLine("G04 P1.5").dwell_s, 1.5);
}

TEST(GcodeArc, FullCircleIjkMeetsTheChordTolerance)
{
  ParserOptions options;
  options.chord_tolerance_mm = 0.005;
  const auto moves = parseAll("G0 X10 Y0\nG2 X10 Y0 I-10 J0 F100\n", options);
  ASSERT_GT(moves.size(), 10u);
  std::vector<Move> arc(moves.begin() + 1, moves.end());
  EXPECT_EQ(arc.front().segment_count, arc.size());
  EXPECT_LE(maxChordDeviation(arc, 0, 0, 10, 0, 1), 0.005 + 1e-9);
  // Clockwise from (10, 0) about the origin: the first chord heads to -Y.
  EXPECT_LT(arc.front().end.y, 0);
  expectNear(arc.back().end, {10, 0, 0});
  // Sagitta bound: n = ceil(2 pi / (2 acos(1 - 0.005 / 10))) = 100.
  EXPECT_EQ(arc.size(), 100u);
}

TEST(GcodeArc, RFormShortAndLongArcs)
{
  // From (0,0) to (10,0), R5: a half circle; G3 (CCW) goes below: centre (5,0).
  auto half = parseAll("G3 X10 Y0 R5\n");
  ASSERT_FALSE(half.empty());
  double min_y = 0, max_y = 0;
  for (const Move& m : half)
  {
    min_y = std::min(min_y, m.end.y);
    max_y = std::max(max_y, m.end.y);
  }
  EXPECT_NEAR(min_y, -5, 0.01);
  EXPECT_NEAR(max_y, 0, 1e-9);

  // Quarter arcs: (0,0) -> (10,10) with R10. G2 R+ : centre (10,0)?  CW short arc has the centre
  // on the right of the chord direction (1,1): centre (10,0).
  auto cw_short = parseAll("G2 X10 Y10 R10\n");
  EXPECT_LE(maxChordDeviation(cw_short, 10, 0, 10, 0, 1), 0.01 + 1e-9);
  auto cw_long = parseAll("G2 X10 Y10 R-10\n");
  EXPECT_LE(maxChordDeviation(cw_long, 0, 10, 10, 0, 1), 0.01 + 1e-9);
  EXPECT_GT(cw_long.size(), cw_short.size() * 2);
}

TEST(GcodeArc, PlanesG18AndG19AndHelix)
{
  // G18 G3 from (X10, Z0) about (0, 0): CCW seen from +Y runs Z+ -> X+ -> Z-, so from +X it
  // heads to -Z.
  auto zx = parseAll("G0 X10\nG18 G3 X0 Z-10 I-10 K0\n");
  ASSERT_GT(zx.size(), 2u);
  EXPECT_LT(zx[1].end.z, 0);
  EXPECT_GT(zx[1].end.x, 0);
  expectNear(zx.back().end, {0, 0, -10});
  // G19 (u = Y, v = Z): from Y10 to Z10 about the origin is a quarter counter-clockwise and three
  // quarters clockwise.
  auto yz = parseAll("G0 Y10\nG19 G2 Y0 Z10 J-10 K0\n");
  auto yz_ccw = parseAll("G0 Y10\nG19 G3 Y0 Z10 J-10 K0\n");
  EXPECT_GT(yz.size(), 2 * yz_ccw.size());
  // Helix: Z moves linearly along a G17 circle.
  auto helix = parseAll("G0 X5\nG17 G3 X5 Y0 Z-3 I-5 J0\n");
  for (size_t k = 1; k < helix.size(); ++k)
  {
    EXPECT_LE(helix[k].end.z, helix[k].start.z);
  }
  EXPECT_DOUBLE_EQ(helix.back().end.z, -3);
}

TEST(GcodeErrors, MalformedLinesGiveLineAndColumn)
{
  struct Case
  {
    const char* program;
    uint32_t line;
    uint32_t column;
    const char* reason_part;
  };
  const Case cases[] = {
      {"G1 X1\nG1 X1 (oops\n", 2, 7, "not closed"},
      {"G1 X\n", 1, 4, "no number"},
      {"G1 X1 X2\n", 1, 7, "twice"},
      {"G7 X1\n", 1, 1, "G7 is not supported"},
      {"G81 X1\n", 1, 1, "G81 is not supported"},
      {"G1 A10\n", 1, 4, "axis A"},
      {"#1=5\n", 1, 1, "macro"},
      {"G1 X1 @\n", 1, 7, "unexpected character '@'"},
      {"G0 G1 X1\n", 1, 4, "same modal group"},
      {"G2 X10 Y0 I4 J0\n", 1, 1, "not on the circle"},
      {"G2 X10\n", 1, 1, "without I/J/K or R"},
      {"G2 X30 R5\n", 1, 8, "smaller than half"},
      {"G1 X1 I5\n", 1, 7, "need G02 or G03"},
      {"X1 F-3\n", 1, 4, "negative feed"},
      {"G80\nX1\n", 2, 1, "without a motion mode"},
      {"G1 X1..2\n", 1, 7, "unexpected character '.'"},
      {"G1 X1\xff\n", 1, 6, "0xff"},
  };
  for (const Case& c : cases)
  {
    SCOPED_TRACE(c.program);
    const ParseError e = parseError(c.program);
    EXPECT_EQ(e.line(), c.line);
    EXPECT_EQ(e.column(), c.column);
    EXPECT_NE(e.reason().find(c.reason_part), std::string::npos) << e.reason();
    EXPECT_NE(std::string(e.what()).find("line " + std::to_string(c.line)), std::string::npos);
  }
}

TEST(GcodeErrors, AnErrorLeavesTheStateAsItWas)
{
  Parser p;
  p.parseLine("G20 G0 X1");
  EXPECT_THROW(p.parseLine("G21 G1 X5 Y2 Y3"), ParseError);
  EXPECT_EQ(p.state().units, Units::kInches);
  EXPECT_EQ(p.state().motion, Motion::kRapid);
  EXPECT_DOUBLE_EQ(p.position().x, 25.4);
  const Block& b = p.parseLine("X2");
  ASSERT_EQ(b.moves.size(), 1u);
  EXPECT_DOUBLE_EQ(b.moves[0].end.x, 50.8);
}

TEST(GcodeReader, StreamsManyLinesAndRejectsAnOversizeLine)
{
  // Lines straddle the reader's 64 KiB chunks; every one must arrive whole and in order.
  std::ostringstream program;
  const int kLines = 50000;
  for (int k = 1; k <= kLines; ++k)
  {
    program << "N" << k << " G1 X" << k << ".25 Y-" << (k % 100) << " F1500\n";
  }
  std::istringstream in(program.str());
  Reader reader(in);
  Move m;
  int count = 0;
  while (reader.nextMove(m))
  {
    ++count;
    ASSERT_EQ(m.block_number, count);
    ASSERT_DOUBLE_EQ(m.end.x, count + 0.25);
  }
  EXPECT_EQ(count, kLines);

  std::istringstream huge("G1 X1\n(" + std::string(100000, 'a') + ")\nX2\n");
  Reader oversize(huge);
  ASSERT_NE(oversize.nextBlock(), nullptr);
  try
  {
    oversize.nextBlock();
    FAIL() << "oversize line accepted";
  }
  catch (const ParseError& e)
  {
    EXPECT_EQ(e.line(), 2u);
    EXPECT_NE(e.reason().find("longer than 4096"), std::string::npos);
  }
}

TEST(GcodeReader, LastLineWithoutNewlineAndBlockDelete)
{
  ParserOptions options;
  options.block_delete = true;
  const auto moves = parseAll("G1 X1\n/G1 X5\nX3", options);
  ASSERT_EQ(moves.size(), 2u);
  EXPECT_DOUBLE_EQ(moves[1].end.x, 3);
  const auto all = parseAll("G1 X1\n/G1 X5\nX3");
  EXPECT_EQ(all.size(), 3u);
}

// A consumer that keeps G53 moves apart (ethernut: the board has one coordinate system) sees
// every G53 move, even one whose numbers equal the program position, and the program position
// is not changed by it: the move after a left-out G53 retract keeps the program's Z.
TEST(GcodeParser, SeparateMachineMovesLeaveTheProgramPositionAlone)
{
  const std::string program = "G90 G00 X0 Y0 Z0\nG53 G00 Z0\nG01 Z-1 F100\nG00 Z25\nG53 Z0\nX40\nG53 Y0\n";
  ParserOptions separate;
  separate.separate_machine_moves = true;
  const auto moves = parseAll(program, separate);
  std::vector<uint32_t> g53_lines;
  std::vector<Move> program_moves;
  for (const Move& m : moves)
  {
    if (m.machine_coordinates)
    {
      g53_lines.push_back(m.line);
    }
    else
    {
      program_moves.push_back(m);
    }
  }
  EXPECT_EQ(g53_lines, (std::vector<uint32_t>{2, 5, 7}));  // line 2 too: Z0 in another frame
  ASSERT_EQ(program_moves.size(), 3u);                     // line 1 goes nowhere from the origin
  expectNear(program_moves[0].start, {0, 0, 0});
  expectNear(program_moves[0].end, {0, 0, -1});
  expectNear(program_moves[2].start, {0, 0, 25});  // after the G53 Z0: still at the program's Z25
  expectNear(program_moves[2].end, {40, 0, 25});

  // Without the option, a G53 target becomes the program position (one frame for everything).
  const auto mixed = parseAll(program);
  ASSERT_FALSE(mixed.empty());
  EXPECT_EQ(std::count_if(mixed.begin(), mixed.end(), [](const Move& m) { return m.machine_coordinates; }), 1);
  expectNear(mixed.back().end, {40, 0, 0});
}
