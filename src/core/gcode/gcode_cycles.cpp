// Canned cycles (G73 G74 G76 G81-G86 G89) expanded into the rapid, feed and dwell moves a control
// makes of them, in the XY plane. The sequence follows the RS-274/NGC description (LinuxCNC's
// G-code reference, "Canned Cycles") and the Haas mill operator's manual: per hole, a rapid in XY
// at the current height, a rapid down to R, the cycle's own moves, and the return to the R plane
// (G99) or the initial level (G98); with L (K on Fanuc) repeats, incremental X/Y step from hole to
// hole.
#include <algorithm>
#include <cmath>
#include <string>

#include "cnc_bridge/gcode/gcode.h"
#include "gcode_internal.h"

namespace cnc_bridge
{
namespace gcode
{
namespace
{
// G73 retract and G83 clearance above the last peck when the options leave it to the dialect.
double peckClearance(const ParserOptions& options)
{
  if (options.peck_clearance_mm >= 0.0)
  {
    return options.peck_clearance_mm;
  }
  // LinuxCNC: 0.010 in (interp's G83_RAPID_DELTA / G73 retract); Haas: setting 22, 0.050 in by
  // default; Fanuc: parameters 5114/5115, taken as the Haas value.
  return options.dialect == Dialect::kLinuxCnc ? 0.010 * kMmPerInch : 0.050 * kMmPerInch;
}
}  // namespace

void Parser::runCycle(const Scan& scan, Step& st)
{
  const uint32_t line = st.line;
  ModalState& next = st.next;
  ModalState::Cycle& c = next.cycle;
  const uint16_t g = next.canned_cycle;
  const std::string name = "G" + std::to_string(g);
  const uint32_t column =
      st.motion_column ? st.motion_column : scan.column[scan.has(kX) ? kX : (scan.has(kY) ? kY : kZ)];
  const double scale = st.scale();
  const bool incremental = next.distance == DistanceMode::kIncremental;
  if (next.plane != Plane::kXY)
  {
    throw ParseError(
        line, column,
        name + " in the " + toString(next.plane) + " plane: canned cycles are supported in the XY plane (G17) only");
  }
  if (next.cutter_comp != CutterComp::kOff || st.comp.on)
  {
    throw ParseError(line, column, name + " with cutter compensation on: cancel it with G40 first");
  }
  // LinuxCNC wants R and Z again whenever the cycle changes (its errors "R clearance plane
  // unspecified in cycle", "Z value unspecified"); Haas and Fanuc keep them across cycles.
  if (options_.dialect == Dialect::kLinuxCnc && state_.canned_cycle != g)
  {
    if (!scan.has(kR) || !scan.has(kZ))
    {
      throw ParseError(line, column, name + " after another motion mode needs R and Z in this block (LinuxCNC)");
    }
  }
  // R and Z are kept as written (in mm) and read in each block's distance mode, as LinuxCNC and
  // the Haas/Fanuc controls do: R absolute, or (G91) from the Z the block starts at; Z absolute,
  // or (G91) from R.
  if (scan.has(kR))
  {
    c.r_word = scan.value[kR] * scale;
    c.have_r = true;
  }
  if (!c.have_r)
  {
    throw ParseError(line, column, name + " needs R, the retract plane, in its first block");
  }
  if (scan.has(kZ))
  {
    c.z_word = scan.value[kZ] * scale;
    c.have_bottom = true;
  }
  if (!c.have_bottom)
  {
    throw ParseError(line, column, name + " needs Z, the bottom of the hole, in its first block");
  }
  // Incremental R is counted from the initial level (the Z before the series of cycles), which
  // is where the tool is in the first block; LinuxCNC's rs274 does the same in later blocks.
  c.r = incremental ? c.initial_z + c.r_word : c.r_word + next.g92_offset.z;
  c.bottom = incremental ? c.r + c.z_word : c.z_word + next.g92_offset.z;
  if (c.bottom > c.r + 1e-9)
  {
    throw ParseError(line, scan.has(kZ) ? scan.column[kZ] : column,
                     name + ": the hole's bottom (Z) is above the R plane; check R and Z (and G90/G91)");
  }
  if (scan.has(kQ))
  {
    if (!(scan.value[kQ] > 0) && (g == 73 || g == 83))
    {
      throw ParseError(line, scan.column[kQ], name + " needs a positive Q (peck depth)");
    }
    c.peck = std::fabs(scan.value[kQ]) * scale;
  }
  if ((g == 73 || g == 83) && !(c.peck > 0))
  {
    throw ParseError(line, column, name + " needs Q, the peck depth");
  }
  if (scan.has(kP))
  {
    c.dwell_s = dwellSeconds(scan, kP);
    c.have_dwell = true;
  }
  if (options_.dialect == Dialect::kLinuxCnc && !c.have_dwell && (g == 82 || g == 86 || g == 89))
  {
    throw ParseError(line, column, name + " needs P, the dwell at the bottom (LinuxCNC)");
  }
  // Repeats: L on Haas and LinuxCNC, K (or L) on Fanuc.
  uint32_t repeats = 1;
  const bool fanuc = options_.dialect == Dialect::kFanuc;
  if (scan.has(kK) && !fanuc)
  {
    throw ParseError(line, scan.column[kK],
                     "K in a canned cycle: repeats are L in the " + std::string(toString(options_.dialect)) +
                         " dialect (K is Fanuc's)");
  }
  if ((scan.has(kI) || scan.has(kJ)) && g != 76)
  {
    throw ParseError(line, scan.column[scan.has(kI) ? kI : kJ], "I/J in " + name + " (only G76 shifts by I/J)");
  }
  for (Word w : {kL, kK})
  {
    if (scan.has(w))
    {
      const double v = scan.value[w];
      if (v < 0 || v != std::floor(v) || v > 9999)
      {
        throw ParseError(line, scan.column[w], "repeats must be a whole number 0..9999");
      }
      repeats = static_cast<uint32_t>(v);
    }
  }
  // Where the tool goes between holes: R (G99) or the level the cycles started from (G98).
  const double clear = next.retract == RetractMode::kRPlane ? c.r : std::max(c.initial_z, c.r);
  // Feeding out of a tapped or bored hole: LinuxCNC's G84/G74/G89 feed all the way to the return
  // level (its G85 to R); Haas and Fanuc feed to R and rapid from there to the initial level.
  const double feed_out = options_.dialect == Dialect::kLinuxCnc && g != 85 ? clear : c.r;
  const double clearance = peckClearance(options_);

  // Shift of G76 away from the wall: I/J, else Q along +X (Haas setting 27's default).
  double shift_x = 0.0, shift_y = 0.0;
  if (g == 76)
  {
    if (scan.has(kI) || scan.has(kJ))
    {
      shift_x = scan.has(kI) ? scan.value[kI] * scale : 0.0;
      shift_y = scan.has(kJ) ? scan.value[kJ] * scale : 0.0;
    }
    else
    {
      shift_x = c.peck;
    }
  }

  const size_t first = st.block.moves.size();
  auto check_count = [&]()
  {
    if (st.block.moves.size() - first > options_.max_cycle_moves)
    {
      throw ParseError(line, column,
                       name + " makes more than " + std::to_string(options_.max_cycle_moves) +
                           " moves (repeats x pecks): check L/K and Q");
    }
  };
  auto go = [&](Motion motion, double x, double y, double z) -> Move*
  {
    if (x == st.position.x && y == st.position.y && z == st.position.z)
    {
      return nullptr;
    }
    Move m = proto(st, motion);
    m.end = {x, y, z};
    m.cycle = g;
    st.block.moves.push_back(m);
    st.position = m.end;
    check_count();
    return &st.block.moves.back();
  };
  auto rapid_z = [&](double z) { return go(Motion::kRapid, st.position.x, st.position.y, z); };
  auto feed_z = [&](double z) { return go(Motion::kLinear, st.position.x, st.position.y, z); };
  // Flags an action at the tool's current point: on the move that got it there.
  auto at_bottom = [&](Move* m, double dwell, SpindleAction action)
  {
    if (!m)
    {
      throw ParseError(line, column, name + ": the hole has no depth (Z equals R)");
    }
    m->dwell_after_s = dwell;
    m->spindle_after = action;
  };
  if (g == 74 || g == 84)
  {
    if (next.spindle == Spindle::kOff)
    {
      throw ParseError(line, column, name + " (tapping) with the spindle off: start it with M03/M04 first");
    }
  }

  // Preliminary motion: below R, first up to R.
  if (st.position.z < c.r)
  {
    rapid_z(c.r);
  }
  for (uint32_t hole = 0; hole < repeats; ++hole)
  {
    double x = st.position.x, y = st.position.y;
    if (incremental)
    {
      x += scan.has(kX) ? scan.value[kX] * scale : 0.0;
      y += scan.has(kY) ? scan.value[kY] * scale : 0.0;
    }
    else
    {
      x = scan.has(kX) ? scan.value[kX] * scale + next.g92_offset.x : x;
      y = scan.has(kY) ? scan.value[kY] * scale + next.g92_offset.y : y;
    }
    // LinuxCNC under G98 goes straight to the hole at the return level (rising on the way if the
    // tool was lower, after a G99 hole); Haas and Fanuc move in XY at the current height.
    const bool rise = options_.dialect == Dialect::kLinuxCnc && next.retract == RetractMode::kInitialLevel;
    go(Motion::kRapid, x, y, rise ? std::max(st.position.z, clear) : st.position.z);
    rapid_z(c.r);
    switch (g)
    {
      case 81:
        feed_z(c.bottom);
        rapid_z(clear);
        break;
      case 82:
        at_bottom(feed_z(c.bottom), c.dwell_s, SpindleAction::kNone);
        rapid_z(clear);
        break;
      case 73:
      case 83:
      {
        // Pecks of Q; G73 backs off by the clearance to break the chip, G83 goes out to R and
        // comes back to the clearance above the last depth.
        // The pecks step down by Q from R as the control counts them; the bound is checked at each.
        for (double depth = c.r - c.peck; depth > c.bottom; depth -= c.peck)  // NOLINT(cert-flp30-c)
        {
          feed_z(depth);
          if (g == 73)
          {
            rapid_z(depth + clearance);
          }
          else
          {
            rapid_z(c.r);
            rapid_z(depth + clearance);
          }
        }
        feed_z(c.bottom);
        rapid_z(clear);
        break;
      }
      case 74:
      case 84:
        // Feed in, reverse at the bottom, feed out to R, spindle back as it was.
        at_bottom(feed_z(c.bottom), c.dwell_s, SpindleAction::kReverse);
        if (Move* out = feed_z(feed_out))
        {
          out->spindle_after = SpindleAction::kResume;
        }
        rapid_z(clear);
        break;
      case 85:
        feed_z(c.bottom);
        feed_z(feed_out);
        rapid_z(clear);
        break;
      case 86:
        at_bottom(feed_z(c.bottom), c.dwell_s, SpindleAction::kStop);
        if (Move* out = rapid_z(clear))
        {
          out->spindle_after = SpindleAction::kResume;
        }
        break;
      case 89:
        at_bottom(feed_z(c.bottom), c.dwell_s, SpindleAction::kNone);
        feed_z(feed_out);
        rapid_z(clear);
        break;
      case 76:
      {
        // Fine boring: oriented stop at the bottom, shift off the wall, out, shift back.
        at_bottom(feed_z(c.bottom), c.dwell_s, SpindleAction::kOrientStop);
        go(Motion::kRapid, x + shift_x, y + shift_y, st.position.z);
        rapid_z(clear);
        if (Move* back = go(Motion::kRapid, x, y, st.position.z))
        {
          back->spindle_after = SpindleAction::kResume;
        }
        break;
      }
      default:
        throw ParseError(line, column, name + " is not supported");
    }
  }
}
}  // namespace gcode
}  // namespace cnc_bridge
