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

// What a cycle's errors point at: the block's line, the column of its motion code (or of its
// first axis word), and the cycle's name ("G83").
struct CycleSite
{
  uint32_t line = 0;
  uint32_t column = 0;
  uint16_t g = 0;
  std::string name;
};

CycleSite cycleSite(const Scan& scan, const Parser::Step& st)
{
  CycleSite site;
  site.line = st.line;
  site.g = st.next.canned_cycle;
  site.name = "G" + std::to_string(site.g);
  site.column = st.motion_column ? st.motion_column : scan.column[scan.has(kX) ? kX : (scan.has(kY) ? kY : kZ)];
  return site;
}

// Where a cycle may run: the XY plane, compensation off; LinuxCNC wants R and Z again whenever
// the cycle changes (its errors "R clearance plane unspecified in cycle", "Z value unspecified");
// Haas and Fanuc keep them across cycles.
void checkCycleAllowed(const Scan& scan, const Parser::Step& st, const CycleSite& site, Dialect dialect,
                       uint16_t previous_cycle)
{
  if (st.next.plane != Plane::kXY)
  {
    throw ParseError(site.line, site.column,
                     site.name + " in the " + toString(st.next.plane) +
                         " plane: canned cycles are supported in the XY plane (G17) only");
  }
  if (st.next.cutter_comp != CutterComp::kOff || st.comp.on)
  {
    throw ParseError(site.line, site.column, site.name + " with cutter compensation on: cancel it with G40 first");
  }
  if (dialect == Dialect::kLinuxCnc && previous_cycle != site.g && (!scan.has(kR) || !scan.has(kZ)))
  {
    throw ParseError(site.line, site.column,
                     site.name + " after another motion mode needs R and Z in this block (LinuxCNC)");
  }
}

// R and Z are kept as written (in mm) and read in each block's distance mode, as LinuxCNC and
// the Haas/Fanuc controls do: R absolute, or (G91) from the Z the block starts at; Z absolute,
// or (G91) from R.
void readRetractAndBottom(const Scan& scan, Parser::Step& st, const CycleSite& site)
{
  ModalState::Cycle& c = st.next.cycle;
  const double scale = st.scale();
  if (scan.has(kR))
  {
    c.r_word = scan.value[kR] * scale;
    c.have_r = true;
  }
  if (!c.have_r)
  {
    throw ParseError(site.line, site.column, site.name + " needs R, the retract plane, in its first block");
  }
  if (scan.has(kZ))
  {
    c.z_word = scan.value[kZ] * scale;
    c.have_bottom = true;
  }
  if (!c.have_bottom)
  {
    throw ParseError(site.line, site.column, site.name + " needs Z, the bottom of the hole, in its first block");
  }
  // Incremental R is counted from the initial level (the Z before the series of cycles), which
  // is where the tool is in the first block; LinuxCNC's rs274 does the same in later blocks.
  const bool incremental = st.next.distance == DistanceMode::kIncremental;
  c.r = incremental ? c.initial_z + c.r_word : c.r_word + st.next.g92_offset.z;
  c.bottom = incremental ? c.r + c.z_word : c.z_word + st.next.g92_offset.z;
  if (c.bottom > c.r + 1e-9)
  {
    throw ParseError(site.line, scan.has(kZ) ? scan.column[kZ] : site.column,
                     site.name + ": the hole's bottom (Z) is above the R plane; check R and Z (and G90/G91)");
  }
}

// Q: the peck depth of G73/G83 (required, positive) or G76's shift off the wall.
void readPeck(const Scan& scan, Parser::Step& st, const CycleSite& site)
{
  ModalState::Cycle& c = st.next.cycle;
  const bool pecking = site.g == 73 || site.g == 83;
  if (scan.has(kQ))
  {
    if (!(scan.value[kQ] > 0) && pecking)
    {
      throw ParseError(site.line, scan.column[kQ], site.name + " needs a positive Q (peck depth)");
    }
    c.peck = std::fabs(scan.value[kQ]) * st.scale();
  }
  if (pecking && !(c.peck > 0))
  {
    throw ParseError(site.line, site.column, site.name + " needs Q, the peck depth");
  }
}

// Repeats: L on Haas and LinuxCNC, K (or L) on Fanuc. I/J belong to G76 alone.
uint32_t readRepeats(const Scan& scan, const CycleSite& site, Dialect dialect)
{
  if (scan.has(kK) && dialect != Dialect::kFanuc)
  {
    throw ParseError(
        site.line, scan.column[kK],
        "K in a canned cycle: repeats are L in the " + std::string(toString(dialect)) + " dialect (K is Fanuc's)");
  }
  if ((scan.has(kI) || scan.has(kJ)) && site.g != 76)
  {
    throw ParseError(site.line, scan.column[scan.has(kI) ? kI : kJ],
                     "I/J in " + site.name + " (only G76 shifts by I/J)");
  }
  uint32_t repeats = 1;
  for (Word w : {kL, kK})
  {
    if (scan.has(w))
    {
      const double v = scan.value[w];
      if (v < 0 || v != std::floor(v) || v > 9999)
      {
        throw ParseError(site.line, scan.column[w], "repeats must be a whole number 0..9999");
      }
      repeats = static_cast<uint32_t>(v);
    }
  }
  return repeats;
}

// The levels and offsets every hole of one cycle block uses (Z in the program's starting frame).
struct HoleLevels
{
  double r = 0.0;          // the R plane
  double bottom = 0.0;     // the hole's bottom
  double clear = 0.0;      // where the tool goes between holes: R (G99) or the initial level (G98)
  double feed_out = 0.0;   // where a tapped or bored hole is fed out to
  double clearance = 0.0;  // G73 back-off, G83 re-entry above the last peck
  double peck = 0.0;       // Q
  double dwell_s = 0.0;    // P at the bottom
  double shift_x = 0.0;    // G76's shift off the wall
  double shift_y = 0.0;
};

HoleLevels holeLevels(const Scan& scan, const Parser::Step& st, const ParserOptions& options)
{
  const ModalState::Cycle& c = st.next.cycle;
  const uint16_t g = st.next.canned_cycle;
  HoleLevels levels;
  levels.r = c.r;
  levels.bottom = c.bottom;
  levels.peck = c.peck;
  levels.dwell_s = c.dwell_s;
  levels.clear = st.next.retract == RetractMode::kRPlane ? c.r : std::max(c.initial_z, c.r);
  // Feeding out of a tapped or bored hole: LinuxCNC's G84/G74/G89 feed all the way to the return
  // level (its G85 to R); Haas and Fanuc feed to R and rapid from there to the initial level.
  levels.feed_out = options.dialect == Dialect::kLinuxCnc && g != 85 ? levels.clear : c.r;
  levels.clearance = peckClearance(options);
  // Shift of G76 away from the wall: I/J, else Q along +X (Haas setting 27's default).
  if (g == 76)
  {
    if (scan.has(kI) || scan.has(kJ))
    {
      const double scale = st.scale();
      levels.shift_x = scan.has(kI) ? scan.value[kI] * scale : 0.0;
      levels.shift_y = scan.has(kJ) ? scan.value[kJ] * scale : 0.0;
    }
    else
    {
      levels.shift_x = c.peck;
    }
  }
  return levels;
}

// The moves of one cycle block, appended to the block: each starts where the last ended, a move
// that would go nowhere is left out, and the count is bounded by ParserOptions::max_cycle_moves.
class CycleMoves
{
 public:
  using MakeMove = Move (*)(const Parser::Step&, Motion);

  CycleMoves(Parser::Step& st, const CycleSite& site, uint32_t max_moves, MakeMove make)
      : st_(st), site_(site), max_moves_(max_moves), make_(make), first_(st.block.moves.size())
  {
  }

  const Vec3& position() const { return st_.position; }

  // \returns the move, or nullptr when the tool is already there.
  Move* go(Motion motion, double x, double y, double z)
  {
    if (x == st_.position.x && y == st_.position.y && z == st_.position.z)
    {
      return nullptr;
    }
    Move m = make_(st_, motion);
    m.end = {x, y, z};
    m.cycle = site_.g;
    st_.block.moves.push_back(m);
    st_.position = m.end;
    if (st_.block.moves.size() - first_ > max_moves_)
    {
      throw ParseError(
          site_.line, site_.column,
          site_.name + " makes more than " + std::to_string(max_moves_) + " moves (repeats x pecks): check L/K and Q");
    }
    return &st_.block.moves.back();
  }
  Move* rapidZ(double z) { return go(Motion::kRapid, st_.position.x, st_.position.y, z); }
  Move* feedZ(double z) { return go(Motion::kLinear, st_.position.x, st_.position.y, z); }

  // Flags an action at the tool's current point: on the move that got it there.
  void atBottom(Move* m, double dwell, SpindleAction action) const
  {
    if (!m)
    {
      throw ParseError(site_.line, site_.column, site_.name + ": the hole has no depth (Z equals R)");
    }
    m->dwell_after_s = dwell;
    m->spindle_after = action;
  }

 private:
  Parser::Step& st_;
  const CycleSite& site_;
  uint32_t max_moves_;
  MakeMove make_;
  size_t first_;
};

// One function per cycle: the moves below R, from the R plane over the hole to the return level.

// G81: feed to the bottom, rapid out.
void drill(CycleMoves& moves, const HoleLevels& h)
{
  moves.feedZ(h.bottom);
  moves.rapidZ(h.clear);
}

// G82: as G81 with a dwell at the bottom.
void drillDwell(CycleMoves& moves, const HoleLevels& h)
{
  moves.atBottom(moves.feedZ(h.bottom), h.dwell_s, SpindleAction::kNone);
  moves.rapidZ(h.clear);
}

// G73/G83: pecks of Q; G73 backs off by the clearance to break the chip, G83 goes out to R and
// comes back to the clearance above the last depth.
void peckDrill(CycleMoves& moves, const HoleLevels& h, bool chip_break)
{
  // The pecks step down by Q from R as the control counts them; the bound is checked at each.
  for (double depth = h.r - h.peck; depth > h.bottom; depth -= h.peck)  // NOLINT(cert-flp30-c)
  {
    moves.feedZ(depth);
    if (!chip_break)
    {
      moves.rapidZ(h.r);
    }
    moves.rapidZ(depth + h.clearance);
  }
  moves.feedZ(h.bottom);
  moves.rapidZ(h.clear);
}

// G74/G84: feed in, reverse at the bottom, feed out, spindle back as it was.
void tap(CycleMoves& moves, const HoleLevels& h)
{
  moves.atBottom(moves.feedZ(h.bottom), h.dwell_s, SpindleAction::kReverse);
  if (Move* out = moves.feedZ(h.feed_out))
  {
    out->spindle_after = SpindleAction::kResume;
  }
  moves.rapidZ(h.clear);
}

// G85: feed in, feed out.
void bore(CycleMoves& moves, const HoleLevels& h)
{
  moves.feedZ(h.bottom);
  moves.feedZ(h.feed_out);
  moves.rapidZ(h.clear);
}

// G86: feed in, spindle stop at the bottom, rapid out, spindle back.
void boreSpindleStop(CycleMoves& moves, const HoleLevels& h)
{
  moves.atBottom(moves.feedZ(h.bottom), h.dwell_s, SpindleAction::kStop);
  if (Move* out = moves.rapidZ(h.clear))
  {
    out->spindle_after = SpindleAction::kResume;
  }
}

// G89: feed in, dwell, feed out.
void boreDwell(CycleMoves& moves, const HoleLevels& h)
{
  moves.atBottom(moves.feedZ(h.bottom), h.dwell_s, SpindleAction::kNone);
  moves.feedZ(h.feed_out);
  moves.rapidZ(h.clear);
}

// G76, fine boring: oriented stop at the bottom, shift off the wall, out, shift back over the
// hole at (x, y).
void fineBore(CycleMoves& moves, const HoleLevels& h, double x, double y)
{
  moves.atBottom(moves.feedZ(h.bottom), h.dwell_s, SpindleAction::kOrientStop);
  moves.go(Motion::kRapid, x + h.shift_x, y + h.shift_y, moves.position().z);
  moves.rapidZ(h.clear);
  if (Move* back = moves.go(Motion::kRapid, x, y, moves.position().z))
  {
    back->spindle_after = SpindleAction::kResume;
  }
}

// The cycle's own moves at the hole (x, y), the tool at R above it.
void holeMoves(CycleMoves& moves, const CycleSite& site, const HoleLevels& h, double x, double y)
{
  switch (site.g)
  {
    case 81:
      drill(moves, h);
      break;
    case 82:
      drillDwell(moves, h);
      break;
    case 73:
    case 83:
      peckDrill(moves, h, site.g == 73);
      break;
    case 74:
    case 84:
      tap(moves, h);
      break;
    case 85:
      bore(moves, h);
      break;
    case 86:
      boreSpindleStop(moves, h);
      break;
    case 89:
      boreDwell(moves, h);
      break;
    case 76:
      fineBore(moves, h, x, y);
      break;
    default:
      throw ParseError(site.line, site.column, site.name + " is not supported");
  }
}
}  // namespace

void Parser::runCycle(const Scan& scan, Step& st)
{
  const CycleSite site = cycleSite(scan, st);
  const uint16_t g = site.g;
  checkCycleAllowed(scan, st, site, options_.dialect, state_.canned_cycle);
  readRetractAndBottom(scan, st, site);
  readPeck(scan, st, site);
  ModalState::Cycle& c = st.next.cycle;
  if (scan.has(kP))
  {
    c.dwell_s = dwellSeconds(scan, kP);
    c.have_dwell = true;
  }
  if (options_.dialect == Dialect::kLinuxCnc && !c.have_dwell && (g == 82 || g == 86 || g == 89))
  {
    throw ParseError(site.line, site.column, site.name + " needs P, the dwell at the bottom (LinuxCNC)");
  }
  const uint32_t repeats = readRepeats(scan, site, options_.dialect);
  const HoleLevels levels = holeLevels(scan, st, options_);
  if ((g == 74 || g == 84) && st.next.spindle == Spindle::kOff)
  {
    throw ParseError(site.line, site.column,
                     site.name + " (tapping) with the spindle off: start it with M03/M04 first");
  }

  CycleMoves moves(st, site, options_.max_cycle_moves, &Parser::proto);
  // Preliminary motion: below R, first up to R.
  if (st.position.z < c.r)
  {
    moves.rapidZ(c.r);
  }
  const double scale = st.scale();
  const bool incremental = st.next.distance == DistanceMode::kIncremental;
  // LinuxCNC under G98 goes straight to the hole at the return level (rising on the way if the
  // tool was lower, after a G99 hole); Haas and Fanuc move in XY at the current height.
  const bool rise = options_.dialect == Dialect::kLinuxCnc && st.next.retract == RetractMode::kInitialLevel;
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
      x = scan.has(kX) ? scan.value[kX] * scale + st.next.g92_offset.x : x;
      y = scan.has(kY) ? scan.value[kY] * scale + st.next.g92_offset.y : y;
    }
    moves.go(Motion::kRapid, x, y, rise ? std::max(st.position.z, levels.clear) : st.position.z);
    moves.rapidZ(c.r);
    holeMoves(moves, site, levels, x, y);
  }
}
}  // namespace gcode
}  // namespace cnc_bridge
