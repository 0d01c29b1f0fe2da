// What the parser's source files share and nobody else needs: the words of a scanned line, the
// working state of one block while it is applied, and the cutter compensation state.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "cnc_bridge/gcode/gcode.h"

namespace cnc_bridge
{
namespace gcode
{
constexpr double kMmPerInch = 25.4;
constexpr double kPi = 3.14159265358979323846;

// Words one block may carry; each letter at most once (G and M have their own lists).
enum Word : uint8_t
{
  kX,
  kY,
  kZ,
  kI,
  kJ,
  kK,
  kR,
  kF,
  kS,
  kT,
  kP,
  kH,
  kD,
  kQ,
  kL,
  kE,
  kWordCount
};

inline int wordIndex(char letter)
{
  switch (letter)
  {
    case 'X':
      return kX;
    case 'Y':
      return kY;
    case 'Z':
      return kZ;
    case 'I':
      return kI;
    case 'J':
      return kJ;
    case 'K':
      return kK;
    case 'R':
      return kR;
    case 'F':
      return kF;
    case 'S':
      return kS;
    case 'T':
      return kT;
    case 'P':
      return kP;
    case 'H':
      return kH;
    case 'D':
      return kD;
    case 'Q':
      return kQ;
    case 'L':
      return kL;
    case 'E':
      return kE;
    default:
      return -1;
  }
}

inline double& axis(Vec3& v, int i)
{
  return i == 0 ? v.x : (i == 1 ? v.y : v.z);
}
inline double axis(const Vec3& v, int i)
{
  return i == 0 ? v.x : (i == 1 ? v.y : v.z);
}

// (u, v, normal) axis indices of each plane, and the centre-offset words along u and v.
struct PlaneAxes
{
  int u, v, w;
  int offset_u, offset_v;
};
inline PlaneAxes planeAxes(Plane plane)
{
  switch (plane)
  {
    case Plane::kXY:
      return {0, 1, 2, kI, kJ};
    case Plane::kZX:
      return {2, 0, 1, kK, kI};
    case Plane::kYZ:
    default:
      return {1, 2, 0, kJ, kK};
  }
}

// The words of one line as scanned, before they are applied.
struct Parser::Scan
{
  double value[kWordCount];
  uint32_t column[kWordCount];
  uint32_t present = 0;  // bit per Word
  uint32_t decimal = 0;  // bit per Word: the number had a decimal point (Haas dwell units)
  // G codes in tenths (G91.1 -> 911) with their columns.
  std::array<int, 8> g{};
  std::array<uint32_t, 8> g_column{};
  uint8_t g_count = 0;
  std::array<uint16_t, Block::kMaxMCodes> m{};
  std::array<uint32_t, Block::kMaxMCodes> m_column{};
  uint8_t m_count = 0;
  bool has(Word w) const { return present & (1u << w); }
  bool hasDecimal(Word w) const { return decimal & (1u << w); }
  bool hasAxis() const { return has(kX) || has(kY) || has(kZ); }
};
using Scan = Parser::Scan;

// An arc in one plane: centre (u, v), start and end radius, start angle and signed sweep.
struct Arc
{
  PlaneAxes p{0, 1, 2, kI, kJ};
  double cu = 0.0, cv = 0.0;
  double rs = 0.0, re = 0.0;
  double a0 = 0.0, sweep = 0.0;
  bool cw = false;
  Vec3 start, end;
};
double sweepBetween(double a0, double a1, bool cw, bool closed);

// "G92.1" for 921: G codes are kept in tenths.
std::string gName(int tenths);

// Cutter compensation between blocks: the last compensated move is held back until the next
// one shows which way the path turns (an outside corner gets an arc of the tool radius round the
// programmed corner, an inside one moves the end to where the two offset paths cross).
struct Parser::Comp
{
  bool on = false;    // G41/G42 in force and the entry move made
  double side = 1.0;  // +1 G41 (tool on the left), -1 G42
  double radius = 0.0;
  // The held move: its offset path (a line, or an arc about (cu, cv) of radius `rad`).
  bool has_held = false;
  Move held;
  bool held_arc = false;
  bool held_cw = false;
  bool held_full = false;  // a full circle (start = end)
  double cu = 0.0, cv = 0.0, rad = 0.0;
  Vec3 start, end;            // offset start and (provisional) end
  Vec3 programmed_end;        // where the programmed path is at the end of the held move
  double tx = 0.0, ty = 0.0;  // unit tangent of the programmed path there
  std::vector<Move> queued;   // Z-only moves after the held one
};

// The modal groups of the G codes this parser reads: one code of each per block (LinuxCNC's G-code
// reference, "Modal Groups"; the G92 family counts as one group here).
enum class ModalGroup : uint8_t
{
  kMotion,      // G00 G01 G02 G03 G80 and the canned cycles
  kPlane,       // G17 G18 G19
  kUnits,       // G20 G21
  kDistance,    // G90 G91
  kRetract,     // G98 G99
  kCutterComp,  // G40 G41 G42
  kPathMode,    // G61 G64 G187
  kG92,         // G92 G92.1 G92.2 G92.3
};

// The working state of one block while it is applied; committed when the block is done.
struct Parser::Step
{
  Block& block;
  ModalState next;
  Vec3 position;
  Comp& comp;  // a copy of the parser's, or (no tool table: compensation can never start) the parser's own
  uint32_t line = 0;
  bool machine_coordinates = false;
  bool motion_word = false;
  uint32_t motion_column = 0;
  int non_modal = 0;  // tenths: 40 (G04), 280, 300, 920, 921, 922, 923
  uint32_t non_modal_column = 0;
  bool comp_changed = false;  // G40/G41/G42 in this block
  bool q_used = false;        // Q taken by this block's G64 (LinuxCNC naive CAM tolerance)
  bool l_used = false;        // L taken by this block's canned cycle or subprogram call
  uint32_t used = 0;          // bit per Word: P, E, H, D taken by a code of this block (finishBlock)
  void use(Word w) { used |= 1u << w; }
  uint8_t groups_seen = 0;  // bit per ModalGroup
  int comp_code = 0;        // tenths: 400, 410, 420 when G40/G41/G42 is in this block
  uint32_t comp_column = 0;

  double scale() const { return next.units == Units::kInches ? kMmPerInch : 1.0; }
};
}  // namespace gcode
}  // namespace cnc_bridge
