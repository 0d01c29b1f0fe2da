// Unit tests of the G-code parser: OpenDNC's Haas program (inch, G18/G17 arcs) end to end, arc
// geometry (IJK and R, every plane, chord tolerance), modal state, and malformed input with line
// and column.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>
#include <vector>

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

// A program the parser refuses, and where and why it must say so.
struct ErrorCase
{
  const char* program;
  uint32_t line;
  uint32_t column;
  const char* reason_part;
};

void expectErrors(const std::vector<ErrorCase>& cases)
{
  for (const ErrorCase& c : cases)
  {
    SCOPED_TRACE(c.program);
    const ParseError e = parseError(c.program);
    EXPECT_EQ(e.line(), c.line);
    EXPECT_EQ(e.column(), c.column);
    EXPECT_NE(e.reason().find(c.reason_part), std::string::npos) << e.reason();
    EXPECT_NE(std::string(e.what()).find("line " + std::to_string(c.line)), std::string::npos);
  }
}

TEST(GcodeErrors, MalformedLinesGiveLineAndColumn)
{
  expectErrors({
      {"G1 X1\nG1 X1 (oops\n", 2, 7, "not closed"},
      {"G1 X\n", 1, 4, "no number"},
      {"G1 X1 X2\n", 1, 7, "twice"},
      {"G7 X1\n", 1, 1, "G7 is not supported"},
      {"G81 X1\n", 1, 1, "G81 needs R"},
      {"G87 X1 R1 Z0\n", 1, 1, "G87"},
      {"G41 D1 X1\n", 1, 1, "needs the tool's radius: give a tool table"},
      {"M98 P100\n", 1, 1, "O100, which is not in this program"},
      {"G1 X1 L2\n", 1, 7, "L (repeats) without"},
      {"G4 X1 P1.\n", 1, 1, "G04 with axis words"},
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
  });
}

// A word no code of its block uses is an error naming the line and the word, as LinuxCNC's rs274
// refuses it (each case checked with `rs274 -g`): X1E39 must not run as a move to X1.
TEST(GcodeErrors, AWordNoCodeOfItsBlockUsesIsAnError)
{
  expectErrors({
      {"G0 X1 Y0\nG1 X1E39 F100\n", 2, 6, "E word with no code in its block to use it"},
      {"G0 X1 P5\n", 1, 7, "P word with no code in its block to use it"},
      {"M3 S100 P2\n", 1, 9, "P word with no code"},
      {"G0 X1 D1\n", 1, 7, "D word with no G41 or G42"},
      {"G40 D1\n", 1, 5, "D word with no G41 or G42"},
      {"G0 X1 H1\n", 1, 7, "H word with no G43"},
      {"G4 P1 H2\n", 1, 7, "H word with no G43"},
  });
  // The codes that use them take them (rs274 accepts these too).
  Parser p;
  EXPECT_NO_THROW(p.parseLine("G43 H1"));
  EXPECT_NO_THROW(p.parseLine("G64 P0.01"));
  EXPECT_NO_THROW(p.parseLine("G4 P1"));
  EXPECT_NO_THROW(p.parseLine("G0 X0 Y0 Z2"));
  EXPECT_NO_THROW(p.parseLine("G82 X1 Y1 Z-1 R1 P1 F100"));
  ParserOptions haas_options;
  haas_options.dialect = Dialect::kHaas;
  Parser haas(haas_options);
  EXPECT_NO_THROW(haas.parseLine("M59 P1103"));  // a machine-specific M code takes its own P
  EXPECT_NO_THROW(p.parseLine("M62 P0"));
  EXPECT_NO_THROW(haas.parseLine("G187 P1 E0.01"));
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

// ---- CAM program features: G92, G04 per dialect, G28/G30, canned cycles, subprograms, cutter
// compensation, path-mode hints. LinuxCNC's rs274 checks the geometry of the same features in
// test_gcode_rs274; these tests check what rs274 cannot see (flags, dialects, refusals).

namespace
{
ParserOptions dialect(Dialect d)
{
  ParserOptions options;
  options.dialect = d;
  return options;
}

std::vector<Block> parseBlocks(const std::string& program, const ParserOptions& options = ParserOptions())
{
  std::istringstream in(program);
  Reader reader(in, options);
  std::vector<Block> blocks;
  while (const Block* b = reader.nextBlock())
  {
    blocks.push_back(*b);
  }
  return blocks;
}

ParseError parseErrorWith(const std::string& program, const ParserOptions& options)
{
  try
  {
    parseAll(program, options);
  }
  catch (const ParseError& e)
  {
    return e;
  }
  ADD_FAILURE() << "no ParseError for: " << program;
  return ParseError(0, 0, "none");
}

void expectSameMoves(const std::vector<Move>& a, const std::vector<Move>& b)
{
  ASSERT_EQ(a.size(), b.size());
  for (size_t k = 0; k < a.size(); ++k)
  {
    SCOPED_TRACE(k);
    expectNear(a[k].start, b[k].start, 1e-9);
    expectNear(a[k].end, b[k].end, 1e-9);
    EXPECT_EQ(a[k].motion, b[k].motion);
  }
}
}  // namespace

TEST(GcodeCam, G92ShiftGivesTheSameMovesAsTheProgramWithoutIt)
{
  const auto shifted = parseAll(
      "G21 G90 G0 X10 Y10 Z5\nG92 X0 Y0\nG1 X5 Y5 F100\nG2 X10 Y0 I5 J0\nG91 G1 X1\nG90 G92.2\nG1 X20\nG92.3\nG1 X0\n"
      "G92.1\nG1 X1 Y1\n");
  const auto plain =
      parseAll("G21 G90 G0 X10 Y10 Z5\nG1 X15 Y15 F100\nG2 X20 Y10 I5 J0\nG91 G1 X1\nG90\nG1 X20\nG1 X10\nG1 X1 Y1\n");
  expectSameMoves(shifted, plain);
}

TEST(GcodeCam, DwellUnitsFollowTheDialect)
{
  EXPECT_DOUBLE_EQ(parseBlocks("G04 P1.5\n")[0].dwell_s, 1.5);   // Haas: a decimal point is seconds
  EXPECT_DOUBLE_EQ(parseBlocks("G04 P1500\n")[0].dwell_s, 1.5);  // Haas: without one, ms
  EXPECT_DOUBLE_EQ(parseBlocks("G4 P2\n", dialect(Dialect::kLinuxCnc))[0].dwell_s, 2.0);
  EXPECT_DOUBLE_EQ(parseBlocks("G04 P1500\n", dialect(Dialect::kFanuc))[0].dwell_s, 1.5);
  EXPECT_DOUBLE_EQ(parseBlocks("G04 X1.5\n", dialect(Dialect::kFanuc))[0].dwell_s, 1.5);
  const ParseError e = parseErrorWith("G0 X1\nG04 P1.5\n", dialect(Dialect::kFanuc));
  EXPECT_EQ(e.line(), 2u);
  EXPECT_EQ(e.column(), 5u);
  EXPECT_NE(e.reason().find("milliseconds"), std::string::npos) << e.reason();
  // A canned cycle's P follows the same rule.
  const auto moves = parseAll("G0 Z10\nM3 S100\nG82 X1 Y1 R2 Z-1 P250 F100\n");
  ASSERT_EQ(moves.size(), 5u);  // Z up, XY, down to R, feed in (dwell), out
  EXPECT_DOUBLE_EQ(moves[3].dwell_after_s, 0.25);
}

TEST(GcodeCam, ReferenceReturnGoesThroughTheIntermediatePointAndIsFlaggedAsMachineMove)
{
  const auto moves = parseAll("G21 G0 X10 Y20 Z30\nG91 G28 Z5\nG90 G0 X1 Y1 Z1\n");
  ASSERT_EQ(moves.size(), 4u);
  expectNear(moves[1].end, {10, 20, 35});  // intermediate point, incremental
  EXPECT_FALSE(moves[1].machine_coordinates);
  expectNear(moves[2].end, {10, 20, 0});  // then Z to the reference point, machine coordinates
  EXPECT_TRUE(moves[2].machine_coordinates);
  EXPECT_TRUE(moves[2].reference_return);
  EXPECT_EQ(moves[2].motion, Motion::kRapid);

  // ethernut's reading (G53 moves kept apart): the reference move is reported, position kept.
  ParserOptions separate;
  separate.separate_machine_moves = true;
  const auto apart = parseAll("G0 X10 Y20 Z30\nG28 Z30\nG1 X11\n", separate);
  ASSERT_EQ(apart.size(), 3u);
  EXPECT_TRUE(apart[1].machine_coordinates);
  expectNear(apart[2].start, {10, 20, 30});

  // A bare G28: every axis on Haas and LinuxCNC, nothing on Fanuc (only named axes move).
  EXPECT_EQ(parseAll("G0 X1 Y2 Z3\nG28\n").back().end.z, 0.0);
  EXPECT_EQ(parseAll("G0 X1 Y2 Z3\nG28\n").back().end.x, 0.0);
  EXPECT_EQ(parseAll("G0 X1 Y2 Z3\nG28\n", dialect(Dialect::kFanuc)).size(), 1u);
  // G30 goes to its own point.
  ParserOptions g30;
  g30.g30_position = {100, 200, 50};
  expectNear(parseAll("G0 X1 Y2 Z3\nG30 Z3\n", g30).back().end, {1, 2, 50});
}

TEST(GcodeCam, CannedCyclesFlagDwellsAndSpindleActions)
{
  // G84: reverse at the bottom, resume at R.
  auto moves = parseAll("G0 X0 Y0 Z10\nM3 S500\nG99 G84 X5 Y5 R2 Z-8 F500\n");
  ASSERT_EQ(moves.size(), 5u);  // Z up; XY rapid, down to R, feed in, feed out
  EXPECT_EQ(moves[3].spindle_after, SpindleAction::kReverse);
  EXPECT_DOUBLE_EQ(moves[3].end.z, -8);
  EXPECT_EQ(moves[4].spindle_after, SpindleAction::kResume);
  EXPECT_DOUBLE_EQ(moves[4].end.z, 2);
  EXPECT_EQ(moves[4].motion, Motion::kLinear);
  for (const Move& m : moves)
  {
    EXPECT_EQ(m.cycle, m.line == 3 ? 84 : 0);
  }
  // G86: spindle stop at the bottom, rapid out, resume.
  moves = parseAll("G0 Z10\nM3 S500\nG98 G86 X1 R2 Z-3 P0.5\n");
  ASSERT_EQ(moves.size(), 5u);
  EXPECT_EQ(moves[3].spindle_after, SpindleAction::kStop);
  EXPECT_DOUBLE_EQ(moves[3].dwell_after_s, 0.5);
  EXPECT_EQ(moves[4].motion, Motion::kRapid);
  EXPECT_DOUBLE_EQ(moves[4].end.z, 10);
  EXPECT_EQ(moves[4].spindle_after, SpindleAction::kResume);
  // G76 (Haas/Fanuc fine boring): oriented stop, shift by Q along +X, out, back.
  moves = parseAll("G0 X0 Y0 Z10\nM3 S500\nG98 G76 X5 Y5 R2 Z-4 Q0.3 F50\n");
  ASSERT_EQ(moves.size(), 7u);
  EXPECT_EQ(moves[3].spindle_after, SpindleAction::kOrientStop);
  expectNear(moves[4].end, {5.3, 5, -4});
  expectNear(moves[5].end, {5.3, 5, 10});
  expectNear(moves[6].end, {5, 5, 10});
  EXPECT_EQ(moves[6].spindle_after, SpindleAction::kResume);
  // LinuxCNC's G76 is a lathe threading cycle: refused, with what to do.
  const ParseError e = parseErrorWith("G76 X1 R2 Z-4\n", dialect(Dialect::kLinuxCnc));
  EXPECT_NE(e.reason().find("threading"), std::string::npos);
  // Tapping with the spindle off is refused.
  EXPECT_NE(parseError("G0 Z5\nG84 X1 R2 Z-4 F100\n").reason().find("spindle off"), std::string::npos);
}

TEST(GcodeCam, CycleRepeatsAreLOnHaasAndKOnFanuc)
{
  const auto haas = parseAll("G0 X0 Y0 Z5\nG91 G99 G81 X10 R-3 Z-4 L3 F100\n");
  const auto fanuc = parseAll("G0 X0 Y0 Z5\nG91 G99 G81 X10 R-3 Z-4 K3 F100\n", dialect(Dialect::kFanuc));
  expectSameMoves(haas, fanuc);
  // Z up first; the first hole: XY, down to R (2, from the initial 5), feed, out to R; then XY,
  // feed, out for each of the other two.
  ASSERT_EQ(haas.size(), 11u);
  expectNear(haas.back().end, {30, 0, 2});
  EXPECT_DOUBLE_EQ(
      std::min_element(haas.begin(), haas.end(), [](const Move& a, const Move& b) { return a.end.z < b.end.z; })->end.z,
      -2);
  const ParseError e = parseError("G0 Z5\nG81 X1 R2 Z-1 K3 F10\n");
  EXPECT_EQ(e.line(), 2u);
  EXPECT_NE(e.reason().find("repeats are L"), std::string::npos);
  // L0 stores the cycle without drilling (Haas).
  EXPECT_TRUE(parseAll("G0 Z5\nG81 X1 R2 Z-1 L0 F10\n").size() == 1u);
}

TEST(GcodeCam, CycleRefusalsKeepLineColumnAndState)
{
  Parser p;
  p.parseLine("G0 X0 Y0 Z10");
  try
  {
    p.parseLine("G83 X1 R2 Z-5 F100");
    ADD_FAILURE() << "G83 without Q accepted";
  }
  catch (const ParseError& e)
  {
    EXPECT_EQ(e.column(), 1u);
    EXPECT_NE(e.reason().find("Q, the peck depth"), std::string::npos);
  }
  EXPECT_EQ(p.state().canned_cycle, 0);
  EXPECT_DOUBLE_EQ(p.position().x, 0.0);
  EXPECT_THROW(p.parseLine("G81 X1 R-2 Z1"), ParseError);  // bottom above R
  EXPECT_THROW(p.parseLine("G18 G81 X1 R2 Z-1"), ParseError);
  const ParseError e = parseError("G0 Z1\nG81 X1 R2 Z-1 Q1000000 F1\nG83 X1 Q0.00001\n");
  EXPECT_EQ(e.line(), 3u);
  EXPECT_NE(e.reason().find("more than"), std::string::npos) << e.reason();
}

TEST(GcodeCam, G80BesideAMotionCodeIsIgnoredAsLinuxCncDoes)
{
  // The safe-start line of Fanuc-style posts: G00 and G80 in one block (one modal group for
  // LinuxCNC, which ignores the G80; two for Fanuc and Haas). The block rapids, the cycle is over.
  for (Dialect d : {Dialect::kLinuxCnc, Dialect::kHaas, Dialect::kFanuc})
  {
    Parser p(dialect(d));
    p.parseLine("G0 X0 Y0 Z5");
    p.parseLine("G81 X1 Y1 R2 Z-1 F100");
    const Block& b = p.parseLine("N1 G00 G17 G21 G40 G49 G80 G90 X5 Y5");
    ASSERT_EQ(b.moves.size(), 1u);
    EXPECT_EQ(b.moves[0].motion, Motion::kRapid);
    EXPECT_EQ(b.moves[0].cycle, 0);
    expectNear(b.moves[0].end, {5, 5, 5});
    EXPECT_EQ(p.state().canned_cycle, 0);
    EXPECT_EQ(p.parseLine("G80 G01 X6 F100").moves.at(0).motion, Motion::kLinear);
  }
  // G80 beside a cycle stays refused: LinuxCNC would drill, Fanuc (one group) would take the last.
  EXPECT_NE(parseError("G0 Z5\nG80 G81 X1 R2 Z-1 F100\n").reason().find("same modal group"), std::string::npos);
}

TEST(GcodeCam, SubprogramsM98AndM97WithRepeatsAndADepthLimit)
{
  const std::string main_part = "G21 G90 G0 X0 Y0 Z5\n";
  const auto m98 = parseAll(main_part + "M98 P100 L2\nG0 X50\nM30\nO100\nG91 G1 X10 F100\nG90\nM99\n%\n");
  const auto m97 = parseAll(main_part + "M97 P500 L2\nG0 X50\nM30\nN500 G91 G1 X10 F100\nG90\nM99\n%\n");
  const auto inline_ = parseAll(main_part + "G91 G1 X10 F100\nX10\nG90 G0 X50\n");
  expectSameMoves(m98, inline_);
  expectSameMoves(m97, inline_);
  // Lines are the file's own: the subprogram's move says line 6.
  EXPECT_EQ(m98[1].line, 6u);
  // Nested calls and a subprogram that calls itself.
  const auto nested = parseAll("M98 P1\nM30\nO1\nM98 P2 L3\nM99\nO2\nG91 G1 X1 F10\nM99\n");
  ASSERT_EQ(nested.size(), 3u);
  EXPECT_DOUBLE_EQ(nested.back().end.x, 3.0);
  const ParseError e = parseError("G0 X0\nM98 P7\nM30\nO7\nG91 G1 X1 F10\nM98 P7\nM99\n");
  EXPECT_EQ(e.line(), 6u);
  EXPECT_EQ(e.column(), 1u);
  EXPECT_NE(e.reason().find("nested deeper than 8"), std::string::npos) << e.reason();
  // Fanuc's P form: the digits before the last four count the runs.
  const auto fanuc = parseAll("M98 P31000\nM30\nO1000\nG91 G1 X1 F10\nM99\n", dialect(Dialect::kFanuc));
  ASSERT_EQ(fanuc.size(), 3u);
  // Repeats of repeats cannot make the reader run for ever.
  ParserOptions few;
  few.max_subprogram_blocks = 1000;
  const ParseError forever = parseErrorWith("M98 P1 L9999\nM30\nO1\nM98 P2 L9999\nM99\nO2\nG91 G1 X1 F10\nM99\n", few);
  EXPECT_NE(forever.reason().find("more than 1000 blocks"), std::string::npos) << forever.reason();
  // M97 is Haas's: refused elsewhere; a file ending inside a subprogram is an error.
  EXPECT_NE(parseErrorWith("M97 P1\n", dialect(Dialect::kFanuc)).reason().find("Haas"), std::string::npos);
  EXPECT_NE(parseError("M98 P1\nM30\nO1\nG1 X1 F1\n").reason().find("end it with M99"), std::string::npos);
}

TEST(GcodeCam, SubprogramsNeedAStreamThatCanBeReadAgain)
{
  // A pipe cannot seek: M98 is refused with its line and column, the moves before it were read.
  struct Pipe : std::stringbuf
  {
    using std::stringbuf::stringbuf;
    pos_type seekoff(off_type, std::ios_base::seekdir, std::ios_base::openmode) override { return pos_type(-1); }
    pos_type seekpos(pos_type, std::ios_base::openmode) override { return pos_type(-1); }
  } pipe("G1 X1 F10\nM98 P1\nM30\nO1\nG1 X2\nM99\n");
  std::istream in(&pipe);
  Reader reader(in);
  Move move;
  ASSERT_TRUE(reader.nextMove(move));
  EXPECT_DOUBLE_EQ(move.end.x, 1.0);
  try
  {
    reader.nextMove(move);
    ADD_FAILURE() << "M98 on a pipe accepted";
  }
  catch (const ParseError& e)
  {
    EXPECT_EQ(e.line(), 2u);
    EXPECT_EQ(e.column(), 1u);
    EXPECT_NE(e.reason().find("read again (a file), not a pipe"), std::string::npos) << e.reason();
  }
}

TEST(GcodeCam, ProgramEndsAtM30AndAtM99InTheMainProgram)
{
  auto blocks = parseBlocks("G1 X1 F10\nM30\nG1 X2\n");
  EXPECT_EQ(blocks.size(), 2u);
  EXPECT_TRUE(blocks.back().program_end);
  blocks = parseBlocks("G1 X1 F10\nM99\nG1 X2\n");
  EXPECT_EQ(blocks.size(), 2u);
  EXPECT_TRUE(blocks.back().subprogram_end);
}

TEST(GcodeCam, PathModeHintsAreKeptInTheModalState)
{
  Parser p;
  p.parseLine("G187 P2 E0.01");
  EXPECT_EQ(p.state().path_mode, PathMode::kBlend);
  EXPECT_EQ(p.state().smoothing_level, 2);
  EXPECT_DOUBLE_EQ(p.state().path_tolerance_mm, 0.01);
  p.parseLine("G103 P5");
  EXPECT_EQ(p.state().lookahead_blocks, 5);
  p.parseLine("G20 G64 P0.001");
  EXPECT_DOUBLE_EQ(p.state().path_tolerance_mm, 0.0254);
  EXPECT_DOUBLE_EQ(p.state().naive_cam_tolerance_mm, 0.0);
  // LinuxCNC G64 P- Q-: Q is the naive CAM detector's tolerance (SheetCam's LinuxCNC post writes
  // "G64 P0.01 q00.01"); it is a hint like P, not a stray cycle word.
  p.parseLine("G21 G64 P0.01 q00.02");
  EXPECT_DOUBLE_EQ(p.state().path_tolerance_mm, 0.01);
  EXPECT_DOUBLE_EQ(p.state().naive_cam_tolerance_mm, 0.02);
  p.parseLine("G20 G64 P0.001 Q0.002");
  EXPECT_NEAR(p.state().naive_cam_tolerance_mm, 0.0508, 1e-12);
  try
  {
    p.parseLine("G1 X1 Q0.01 F100");
    ADD_FAILURE() << "Q without G64 or a canned cycle was accepted";
  }
  catch (const ParseError& e)
  {
    EXPECT_EQ(e.reason(), "Q without a canned cycle");
  }
  p.parseLine("G61");
  EXPECT_EQ(p.state().path_mode, PathMode::kExactStop);
}

TEST(GcodeCam, CutterCompensationOffsetsTheContourWithTheToolTable)
{
  ParserOptions options;
  options.tool_table =
      std::make_shared<ToolTable>(ToolTable::parseYaml("tools:\n  1: {diameter: 4.0}\n  2: {radius: 1}\n", "t.yaml"));
  // A 20 x 20 square climbed on the outside (G41, counter-clockwise round the outside... the
  // tool left of a clockwise path around the square's outside).
  const auto moves = parseAll("G0 X-10 Y0 Z1\nG1 Z-1 F100\nG41 D1 X0 Y0\nY20\nX20\nY0\nX0\nG40 X-10 Y-10\n", options);
  // Offset of 2 mm to the left of travel: going +Y along X=0, the tool is at X=-2.
  bool saw_left = false;
  for (const Move& m : moves)
  {
    if (m.line == 4 && m.motion == Motion::kLinear)
    {
      EXPECT_NEAR(m.end.x, -2.0, 1e-9);
      EXPECT_NEAR(m.end.y, 20.0, 1e-9);
      EXPECT_TRUE(m.compensated);
      saw_left = true;
    }
  }
  EXPECT_TRUE(saw_left);
  // Outside corners are rounded with the tool radius about the programmed corner.
  for (const Move& m : moves)
  {
    if (m.compensated && (m.motion == Motion::kArcCw || m.motion == Motion::kArcCcw))
    {
      const double r = std::min({std::hypot(m.end.x - 0, m.end.y - 20), std::hypot(m.end.x - 20, m.end.y - 20),
                                 std::hypot(m.end.x - 20, m.end.y - 0), std::hypot(m.end.x, m.end.y)});
      EXPECT_NEAR(r, 2.0, 1e-6);
    }
  }
  // The exit move ends on the programmed point.
  expectNear(moves.back().end, {-10, -10, -1});
  EXPECT_FALSE(moves.back().compensated);
  // A tool not in the table, an arc as the entry move, a tool too big for an inside arc.
  EXPECT_NE(parseErrorWith("G41 D9 X1\n", options).reason().find("tool 9 is not in the tool table"), std::string::npos);
  EXPECT_NE(parseErrorWith("G0 X-5 Y0\nG41 D1 G2 X5 Y0 I5 J0 F10\n", options).reason().find("straight line"),
            std::string::npos);
  EXPECT_NE(parseErrorWith("G0 X-5 Y0\nG41 D1 G1 X0 Y0 F10\nG3 X2 Y0 I1 J0\nG40 G1 X5 Y-5\n", options)
                .reason()
                .find("larger than this arc"),
            std::string::npos);
}

TEST(GcodeCam, CutterCompensationEntryIntoAnInsideCornerEndsOnTheOffsetLine)
{
  ParserOptions options;
  options.tool_table = std::make_shared<ToolTable>(ToolTable::parseYaml("tools:\n  1: {radius: 1}\n", "t.yaml"));
  // Entry along -X (G41: the tool 1 mm on the -Y side), then a counter-clockwise lead-in arc that
  // turns left, into the tool's side: the entry ends where the entry line moved by the radius
  // (Y = 9) meets the arc moved by it (radius 4 about (-5, 10)), as rs274 ends it (-8.8730, 9.0000);
  // not where the path from the uncompensated start would meet it.
  const auto moves =
      parseAll("G0 X0 Y10 Z1\nG1 Z-1 F100\nG41 D1 X-10 Y10\nG3 X-5 Y5 I5 J0\nG1 X20\nG40 X25 Y0\n", options);
  ASSERT_GE(moves.size(), 3u);
  expectNear(moves[2].end, {-5 - std::sqrt(15.0), 9, -1}, 1e-9);
  EXPECT_EQ(moves[2].line, 3u);
  // With a tool too big for that, the offset line misses the offset arc: refused at the arc.
  options.tool_table = std::make_shared<ToolTable>(ToolTable::parseYaml("tools:\n  1: {radius: 3}\n", "t.yaml"));
  const ParseError e = parseErrorWith("G0 X0 Y10 Z1\nG1 Z-1 F100\nG41 D1 X-10 Y10\nG3 X-5 Y5 I5 J0\nG1 X20\n", options);
  EXPECT_EQ(e.line(), 4u);
  EXPECT_NE(e.reason().find("do not meet"), std::string::npos) << e.reason();
}

TEST(GcodeCam, ToolTablesInLinuxCncAndYamlForm)
{
  std::istringstream tbl("T1 P1 D0.25 Z+1.0 ;quarter inch\n\n;comment\nT7 P2 D6 Z0\n");
  const ToolTable inch = ToolTable::parseLinuxCnc(tbl, "tools.tbl", Units::kInches);
  EXPECT_DOUBLE_EQ(inch.radius(1), 0.125 * 25.4);
  EXPECT_DOUBLE_EQ(inch.radius(7), 3 * 25.4);
  EXPECT_LT(inch.radius(2), 0);
  std::istringstream bad("T1 P1 Dx\n");
  EXPECT_THROW(ToolTable::parseLinuxCnc(bad, "bad.tbl"), cnc_bridge::ConfigError);
  EXPECT_THROW(ToolTable::parseYaml("tools: [1, 2]\n", "bad.yaml"), cnc_bridge::ConfigError);
  EXPECT_THROW(ToolTable::parseYaml("tools:\n  3: {length: 2}\n", "bad.yaml"), cnc_bridge::ConfigError);
  EXPECT_THROW(parseDialect("okuma"), cnc_bridge::ConfigError);
  EXPECT_EQ(parseDialect("LinuxCNC"), Dialect::kLinuxCnc);
}
