// Applying the words of one scanned line to the modal state, in the order of execution of RS-274
// (LinuxCNC's G-code reference, "G-code Order of Execution"; docs/gcode.md): the G codes by modal
// group, then F S T, the M codes, a dwell, cutter compensation on/off, the G92 family, and last the
// motion (a reference return, a canned cycle, a straight move or an arc). Each step reads the words
// and the state the earlier steps left; a ParseError anywhere leaves the parser's state as it was
// (parseLine applies the words on a copy).
#include <algorithm>
#include <cmath>
#include <string>

#include "gcode_internal.h"

namespace cnc_bridge
{
namespace gcode
{
namespace
{
using Step = Parser::Step;

// ---- G codes, one function per modal group or concern. ----

void claimGroup(Step& st, ModalGroup group, uint32_t column)
{
  const auto bit = static_cast<uint8_t>(1u << static_cast<unsigned>(group));
  if (st.groups_seen & bit)
  {
    throw ParseError(st.line, column, "two G codes of the same modal group in one block");
  }
  st.groups_seen |= bit;
}

bool groupSeen(const Step& st, ModalGroup group)
{
  return st.groups_seen & (1u << static_cast<unsigned>(group));
}

// G04, G28, G30 and the G92 family act on this block only, one of them per block.
void claimNonModal(Step& st, int code, uint32_t column)
{
  if (st.non_modal)
  {
    throw ParseError(st.line, column,
                     gName(code) + " and " + gName(st.non_modal) + " in one block: give each its own block");
  }
  st.non_modal = code;
  st.non_modal_column = column;
}

void selectMotion(Step& st, Motion motion, uint16_t cycle, uint32_t column)
{
  claimGroup(st, ModalGroup::kMotion, column);
  st.next.motion = motion;
  if (cycle && st.next.canned_cycle == 0)
  {
    st.next.cycle.initial_z = st.position.z;  // the G98 level of this series of cycles
  }
  st.next.canned_cycle = cycle;
  st.motion_word = true;
  st.motion_column = column;
}

// G00 G01 G02 G03, G80 and the canned cycles. \returns false for a code of another group.
bool applyMotionCode(Step& st, int code, uint32_t column, Dialect dialect)
{
  switch (code)
  {
    case 0:
      selectMotion(st, Motion::kRapid, 0, column);
      return true;
    case 10:
      selectMotion(st, Motion::kLinear, 0, column);
      return true;
    case 20:
      selectMotion(st, Motion::kArcCw, 0, column);
      return true;
    case 30:
      selectMotion(st, Motion::kArcCcw, 0, column);
      return true;
    case 800:
      claimGroup(st, ModalGroup::kMotion, column);
      st.next.motion = Motion::kNone;
      st.next.canned_cycle = 0;
      return true;
    case 730:
    case 740:
    case 810:
    case 820:
    case 830:
    case 840:
    case 850:
    case 860:
    case 890:
      selectMotion(st, Motion::kNone, static_cast<uint16_t>(code / 10), column);
      return true;
    case 760:
      if (dialect == Dialect::kLinuxCnc)
      {
        throw ParseError(st.line, column,
                         "G76 is LinuxCNC's lathe threading cycle, which is not supported; for a fine boring "
                         "cycle (Haas/Fanuc G76) choose the haas or fanuc dialect");
      }
      selectMotion(st, Motion::kNone, 76, column);
      return true;
    case 870:
    case 880:
      throw ParseError(
          st.line, column,
          gName(code) + " (back boring / manual boring cycle) is not supported; expand it into G00/G01 moves");
    default:
      return false;
  }
}

// G04 G28 G30 G53 G92 G92.1 G92.2 G92.3: codes for this block only.
bool applyNonModalCode(Step& st, int code, uint32_t column)
{
  switch (code)
  {
    case 40:
    case 280:
    case 300:
      claimNonModal(st, code, column);
      return true;
    case 920:
    case 921:
    case 922:
    case 923:
      claimGroup(st, ModalGroup::kG92, column);
      claimNonModal(st, code, column);
      return true;
    case 530:
      st.machine_coordinates = true;
      return true;
    default:
      return false;
  }
}

// G17-G19 plane, G20/G21 units, G90/G91 distance mode, G98/G99 cycle return level.
bool applyModeCode(Step& st, int code, uint32_t column)
{
  ModalState& next = st.next;
  switch (code)
  {
    case 170:
      claimGroup(st, ModalGroup::kPlane, column);
      next.plane = Plane::kXY;
      return true;
    case 180:
      claimGroup(st, ModalGroup::kPlane, column);
      next.plane = Plane::kZX;
      return true;
    case 190:
      claimGroup(st, ModalGroup::kPlane, column);
      next.plane = Plane::kYZ;
      return true;
    case 200:
      claimGroup(st, ModalGroup::kUnits, column);
      next.units = Units::kInches;
      return true;
    case 210:
      claimGroup(st, ModalGroup::kUnits, column);
      next.units = Units::kMillimetres;
      return true;
    case 900:
      claimGroup(st, ModalGroup::kDistance, column);
      next.distance = DistanceMode::kAbsolute;
      return true;
    case 910:
      claimGroup(st, ModalGroup::kDistance, column);
      next.distance = DistanceMode::kIncremental;
      return true;
    case 980:
      claimGroup(st, ModalGroup::kRetract, column);
      next.retract = RetractMode::kInitialLevel;
      return true;
    case 990:
      claimGroup(st, ModalGroup::kRetract, column);
      next.retract = RetractMode::kRPlane;
      return true;
    default:
      return false;
  }
}

// G40 G41 G42: only noted here; selectCutterComp() acts on it once D and the plane are known.
bool applyCutterCompCode(Step& st, int code, uint32_t column)
{
  if (code != 400 && code != 410 && code != 420)
  {
    return false;
  }
  claimGroup(st, ModalGroup::kCutterComp, column);
  st.comp_code = code;
  st.comp_column = column;
  return true;
}

// G61 G64 G187 G103: path-mode hints for the control; the geometry does not change.
bool applyPathModeCode(const Scan& scan, Step& st, int code, uint32_t column)
{
  ModalState& next = st.next;
  switch (code)
  {
    case 610:
      claimGroup(st, ModalGroup::kPathMode, column);
      next.path_mode = PathMode::kExactStop;
      return true;
    case 640:
      claimGroup(st, ModalGroup::kPathMode, column);
      next.path_mode = PathMode::kBlend;
      next.path_tolerance_mm = scan.has(kP) ? scan.value[kP] : 0.0;  // scaled with the units later
      st.use(kP);
      // LinuxCNC G64 P- Q-: Q is the naive CAM detector's tolerance (CAM posts write it).
      next.naive_cam_tolerance_mm = scan.has(kQ) ? scan.value[kQ] : 0.0;
      st.q_used = scan.has(kQ);
      return true;
    case 1870:
      // Haas G187: P1/P2/P3 rough/medium/finish smoothing, E corner tolerance; bare G187: default.
      claimGroup(st, ModalGroup::kPathMode, column);
      next.path_mode = PathMode::kBlend;
      next.smoothing_level = scan.has(kP) ? static_cast<int32_t>(scan.value[kP]) : 0;
      next.path_tolerance_mm = scan.has(kE) ? scan.value[kE] : 0.0;
      st.use(kP);
      st.use(kE);
      return true;
    case 1030:
      // Haas G103: limit look-ahead to P blocks (P0 or none: the control's maximum).
      next.lookahead_blocks = scan.has(kP) ? static_cast<int32_t>(scan.value[kP]) : 0;
      st.use(kP);
      return true;
    default:
      return false;
  }
}

// Accepted without effect on the programmed geometry: tool length offset (G43/G49: the offset
// values are in the control), work offsets (G54..G59: likewise), feed per minute (G94, the only
// feed mode we support), and the cancel codes CAM posts put in their safe start line: polar
// coordinates off (G15), mirror image off (G50.1), rotation off (G69), and incremental arc centres
// (G91.1), the only centre mode we read.
bool acceptedWithoutEffect(int code)
{
  switch (code)
  {
    case 911:
    case 150:
    case 430:
    case 490:
    case 501:
    case 540:
    case 550:
    case 560:
    case 570:
    case 580:
    case 590:
    case 690:
    case 940:
      return true;
    default:
      return false;
  }
}

void applyGCodes(const Scan& scan, Step& st, Dialect dialect)
{
  // Beside G00-G03 ("G00 G17 G40 G49 G80 G90", the safe-start line of Fanuc-style posts) G80 adds
  // nothing: LinuxCNC ignores it (interp_read.cc, read_g), Fanuc and Haas keep it in a group of its
  // own, and either way the block moves in that mode with no cycle.
  const bool skip_g80 = std::any_of(scan.g.begin(), scan.g.begin() + scan.g_count,
                                    [](int g) { return g == 0 || g == 10 || g == 20 || g == 30; });
  for (uint8_t k = 0; k < scan.g_count; ++k)
  {
    const uint32_t column = scan.g_column[k];
    const int code = scan.g[k];
    if (code == 800 && skip_g80)
    {
      continue;
    }
    const bool known = applyMotionCode(st, code, column, dialect) || applyNonModalCode(st, code, column) ||
                       applyModeCode(st, code, column) || applyCutterCompCode(st, code, column) ||
                       applyPathModeCode(scan, st, code, column) || acceptedWithoutEffect(code);
    if (!known)
    {
      throw ParseError(st.line, column, gName(code) + " is not supported");
    }
    if (code == 430)
    {
      st.use(kH);  // G43 H: the offset number (its value is in the control)
    }
  }
  // The tolerances of G64/G187 are in the block's units, which its G20/G21 may have just set.
  if (st.next.path_mode == PathMode::kBlend && groupSeen(st, ModalGroup::kPathMode))
  {
    st.next.path_tolerance_mm *= st.scale();
    st.next.naive_cam_tolerance_mm *= st.scale();
  }
}

// ---- F S T and the M codes (spindle, tool, coolant; stops and calls are reported). ----

void applyFeedSpindleTool(const Scan& scan, Step& st)
{
  if (scan.has(kF))
  {
    if (scan.value[kF] < 0)
    {
      throw ParseError(st.line, scan.column[kF], "negative feed rate");
    }
    st.next.feed_mm_per_min = scan.value[kF] * st.scale();
  }
  if (scan.has(kS))
  {
    if (scan.value[kS] < 0)
    {
      throw ParseError(st.line, scan.column[kS], "negative spindle speed");
    }
    st.next.spindle_rpm = scan.value[kS];
  }
  if (scan.has(kT))
  {
    if (scan.value[kT] < 0 || scan.value[kT] != std::floor(scan.value[kT]) || scan.value[kT] > 1e9)
    {
      throw ParseError(st.line, scan.column[kT], "malformed T tool number");
    }
    st.next.selected_tool = static_cast<int32_t>(scan.value[kT]);
  }
}

// M97 P (Haas: the N label P in this file) or M98 P (the O label P), L times.
void callSubprogram(const Scan& scan, Step& st, bool local, uint32_t column, Dialect dialect)
{
  Block& block = st.block;
  if (local && dialect != Dialect::kHaas)
  {
    throw ParseError(st.line, column,
                     "M97 (local subprogram call) is a Haas code; choose the haas dialect, or call an O subprogram "
                     "with M98");
  }
  if (block.call.kind != CallKind::kNone)
  {
    throw ParseError(st.line, column, "two subprogram calls in one block");
  }
  if (!scan.has(kP) || scan.value[kP] < 0 || scan.value[kP] != std::floor(scan.value[kP]) || scan.value[kP] > 1e12)
  {
    throw ParseError(
        st.line, column,
        std::string(local ? "M97 needs P, the N number" : "M98 needs P, the O number") + " of the subprogram to call");
  }
  st.use(kP);
  auto p = static_cast<int64_t>(scan.value[kP]);
  uint32_t repeats = 1;
  // Fanuc: M98 P00021000 runs O1000 twice (the digits before the last four count the runs).
  if (!local && dialect == Dialect::kFanuc && p > 9999 && !scan.has(kL))
  {
    repeats = static_cast<uint32_t>(p / 10000);
    p %= 10000;
  }
  if (scan.has(kL))
  {
    const double l = scan.value[kL];
    if (l < 0 || l != std::floor(l) || l > 9999)
    {
      throw ParseError(st.line, scan.column[kL], "L (subprogram repeats) must be a whole number 0..9999");
    }
    repeats = static_cast<uint32_t>(l);
    st.l_used = true;
  }
  block.call.kind = local ? CallKind::kLocal : CallKind::kSubprogram;
  block.call.label = p;
  block.call.repeats = repeats;
  block.call.column = column;
}

void applyMCode(const Scan& scan, Step& st, uint16_t code, uint32_t column, Dialect dialect)
{
  Block& block = st.block;
  ModalState& next = st.next;
  switch (code)
  {
    case 0:
    case 1:
      block.program_stop = true;
      break;
    case 2:
    case 30:
      block.program_end = true;
      break;
    case 3:
      next.spindle = Spindle::kClockwise;
      break;
    case 4:
      next.spindle = Spindle::kCounterClockwise;
      break;
    case 5:
      next.spindle = Spindle::kOff;
      break;
    case 6:
      block.tool_change = true;
      next.tool = next.selected_tool;
      break;
    case 7:
    case 8:
      next.coolant = true;
      break;
    case 9:
      next.coolant = false;
      break;
    case 97:
    case 98:
      callSubprogram(scan, st, code == 97, column, dialect);
      break;
    case 99:
      if (scan.has(kP))
      {
        throw ParseError(st.line, scan.column[kP],
                         "M99 P (a jump to a block) is not supported: only M99 returning from a subprogram");
      }
      block.subprogram_end = true;
      break;
    default:
      // Machine-specific: reported in m_codes; its P and E words are its own (LinuxCNC M62-M68,
      // Haas M59 P), as the control reads them.
      st.use(kP);
      st.use(kE);
      break;
  }
}

void applyMCodes(const Scan& scan, Step& st, Dialect dialect)
{
  for (uint8_t k = 0; k < scan.m_count; ++k)
  {
    st.block.m_codes[st.block.m_count++] = scan.m[k];
    applyMCode(scan, st, scan.m[k], scan.m_column[k], dialect);
  }
}

// ---- Cutter compensation on/off (G40/G41/G42). ----

// The radius G41/G42 offsets by: that of tool D in the tool table (LinuxCNC: the tool in the
// spindle when D is missing; tool 0 has none).
double compensationRadius(const Scan& scan, const Step& st, const ParserOptions& options)
{
  const int code = st.comp_code;
  int32_t tool = st.next.tool;
  if (scan.has(kD))
  {
    const double d = scan.value[kD];
    if (d < 0 || d != std::floor(d) || d > 1e9)
    {
      throw ParseError(st.line, scan.column[kD], "malformed D offset number");
    }
    tool = static_cast<int32_t>(d);
  }
  else if (options.dialect != Dialect::kLinuxCnc)
  {
    throw ParseError(st.line, st.comp_column, gName(code) + " needs D, the offset (tool number) whose radius to use");
  }
  const double radius = tool == 0 ? 0.0 : options.tool_table->radius(tool);
  if (radius < 0)
  {
    throw ParseError(st.line, scan.has(kD) ? scan.column[kD] : st.comp_column,
                     "tool " + std::to_string(tool) + " is not in the tool table: add its diameter there");
  }
  return radius;
}

void selectCutterComp(const Scan& scan, Step& st, const ParserOptions& options)
{
  const int code = st.comp_code;
  if (code == 0)
  {
    return;
  }
  if (code == 400)
  {
    st.next.cutter_comp = CutterComp::kOff;
    st.next.comp_radius_mm = 0.0;
    st.comp_changed = true;
    return;
  }
  st.use(kD);  // G41/G42 D: the offset whose radius to use
  if (!options.tool_table)
  {
    throw ParseError(st.line, st.comp_column,
                     gName(code) +
                         " cutter compensation needs the tool's radius: give a tool table (~tool_table: a LinuxCNC "
                         ".tbl or YAML file with the diameter of the D tool)");
  }
  if (st.next.plane != Plane::kXY)
  {
    throw ParseError(st.line, st.comp_column,
                     gName(code) + " cutter compensation is supported in the XY plane (G17) only");
  }
  st.next.comp_radius_mm = compensationRadius(scan, st, options);
  st.next.cutter_comp = code == 410 ? CutterComp::kLeft : CutterComp::kRight;
  st.comp_changed = true;
}

// ---- G92 family: shift the program's numbers (the moves stay in the starting frame). ----

bool isG92Family(int non_modal)
{
  return non_modal >= 920 && non_modal <= 923;
}

void applyG92(const Scan& scan, Step& st)
{
  ModalState& next = st.next;
  if (st.non_modal == 920)
  {
    if (!scan.hasAxis())
    {
      throw ParseError(st.line, st.non_modal_column, "G92 needs the axes to set (X, Y and/or Z)");
    }
    const Word axes[3] = {kX, kY, kZ};
    for (int a = 0; a < 3; ++a)
    {
      if (scan.has(axes[a]))
      {
        // The current point is to read as the given number from now on.
        axis(next.g92_offset, a) = axis(st.position, a) - scan.value[axes[a]] * st.scale();
      }
    }
    next.g92_saved = next.g92_offset;
  }
  else
  {
    if (scan.hasAxis())
    {
      throw ParseError(st.line, st.non_modal_column, gName(st.non_modal) + " takes no axis words");
    }
    if (st.non_modal == 921)
    {
      next.g92_offset = Vec3();
      next.g92_saved = Vec3();
    }
    else if (st.non_modal == 922)
    {
      next.g92_offset = Vec3();
    }
    else
    {
      next.g92_offset = next.g92_saved;
    }
  }
  if (st.motion_word)
  {
    throw ParseError(st.line, st.motion_column, "a motion code in a G92 block: give the move its own block");
  }
}

// ---- Motion. ----

bool hasCentreOrRadius(const Scan& scan)
{
  return scan.has(kI) || scan.has(kJ) || scan.has(kK) || scan.has(kR);
}

Word firstCentreOrRadiusWord(const Scan& scan)
{
  return scan.has(kI) ? kI : (scan.has(kJ) ? kJ : (scan.has(kK) ? kK : kR));
}

// Where the axis words of the block send the tool: G53 machine numbers, incremental, or absolute
// program numbers shifted by G92.
Vec3 axisTarget(const Scan& scan, const Step& st)
{
  Vec3 target = st.position;
  const Word axes[3] = {kX, kY, kZ};
  for (int a = 0; a < 3; ++a)
  {
    if (scan.has(axes[a]))
    {
      const double v = scan.value[axes[a]] * st.scale();
      if (st.machine_coordinates)
      {
        axis(target, a) = v;  // G53: machine numbers, no G92 shift, never incremental
      }
      else if (st.next.distance == DistanceMode::kIncremental)
      {
        axis(target, a) += v;
      }
      else
      {
        axis(target, a) = v + axis(st.next.g92_offset, a);
      }
    }
  }
  return target;
}

// A word no code of its block uses is an error, as in LinuxCNC's rs274 ("E word with no G70, G76,
// M66, M67 or M68 to use it"): a typo (X1E39) must stop the program, not change where the tool goes.
// X Y Z I J K R L Q are checked where motion and cycles read them; F S T always set their values.
void refuseUnusedWords(const Scan& scan, const Step& st)
{
  static const struct
  {
    Word word;
    const char* message;
  } kUsers[] = {
      {kE, "E word with no code in its block to use it (Haas G187, a machine-specific M code)"},
      {kP,
       "P word with no code in its block to use it (G04, G64, a canned cycle, G103, G187, M97, M98, a "
       "machine-specific M code)"},
      {kH, "H word with no G43 in its block to use it"},
      {kD, "D word with no G41 or G42 in its block to use it"},
  };
  for (const auto& user : kUsers)
  {
    if (scan.has(user.word) && !(st.used & (1u << user.word)))
    {
      throw ParseError(st.line, scan.column[user.word], user.message);
    }
  }
}

// I/J/K/R in a block without axis words: an error either way, worded for what is missing.
[[noreturn]] void refuseCentreWithoutTarget(const Scan& scan, const Step& st)
{
  const Word w = firstCentreOrRadiusWord(scan);
  if (st.motion_word && (st.next.motion == Motion::kArcCw || st.next.motion == Motion::kArcCcw))
  {
    throw ParseError(st.line, scan.column[w], "arc without an end point (X/Y/Z)");
  }
  throw ParseError(st.line, scan.column[w], "I/J/K/R words without an arc");
}
}  // namespace

void Parser::applyWords(const Scan& scan, Step& st)
{
  applyGCodes(scan, st, options_.dialect);
  applyFeedSpindleTool(scan, st);
  applyMCodes(scan, st, options_.dialect);
  if (st.non_modal == 40)
  {
    applyDwell(scan, st);
  }
  selectCutterComp(scan, st, options_);
  if (isG92Family(st.non_modal))
  {
    applyG92(scan, st);
  }
  else
  {
    applyMotion(scan, st);
  }
  finishBlock(scan, st);
}

void Parser::applyDwell(const Scan& scan, Step& st) const
{
  const bool fanuc_x = options_.dialect == Dialect::kFanuc && scan.has(kX) && !scan.has(kP);
  if (!scan.has(kP) && !fanuc_x)
  {
    throw ParseError(st.line, st.non_modal_column,
                     std::string("G04 needs a P word (dwell ") +
                         (options_.dialect == Dialect::kHaas
                              ? "seconds with a decimal point, milliseconds without)"
                              : (options_.dialect == Dialect::kFanuc ? "milliseconds, or X in seconds)" : "seconds)")));
  }
  st.block.dwell_s = dwellSeconds(scan, fanuc_x ? kX : kP);
  st.use(kP);
  if (scan.has(kY) || scan.has(kZ) || (scan.has(kX) && !fanuc_x))
  {
    throw ParseError(st.line, st.non_modal_column, "G04 with axis words: put the move in its own block");
  }
  if (st.motion_word || hasCentreOrRadius(scan))
  {
    throw ParseError(st.line, st.non_modal_column, "G04 with motion words: put the move in its own block");
  }
}

void Parser::applyMotion(const Scan& scan, Step& st)
{
  if (st.non_modal == 280 || st.non_modal == 300)
  {
    if (st.motion_word)
    {
      throw ParseError(st.line, st.motion_column, "a motion code in a G28/G30 block: give the move its own block");
    }
    referenceReturn(scan, st, st.non_modal == 300);
    return;
  }
  const bool has_axis = scan.hasAxis() && st.non_modal != 40;
  if (st.next.canned_cycle && (has_axis || (st.motion_word && scan.has(kR))))
  {
    if (st.machine_coordinates)
    {
      throw ParseError(st.line, st.motion_column ? st.motion_column : 1, "G53 with a canned cycle");
    }
    runCycle(scan, st);
    st.l_used = true;
    st.use(kP);  // the dwell at the bottom
  }
  else if (has_axis)
  {
    moveToAxisWords(scan, st);
  }
  else if (hasCentreOrRadius(scan))
  {
    refuseCentreWithoutTarget(scan, st);
  }
  else if (st.comp_changed && st.next.cutter_comp == CutterComp::kOff)
  {
    compensationOff(st, false);
  }
  else if (st.comp_changed)
  {
    compensationOn(st);
  }
}

void Parser::moveToAxisWords(const Scan& scan, Step& st)
{
  if (st.next.motion == Motion::kNone)
  {
    throw ParseError(st.line, scan.column[scan.has(kX) ? kX : (scan.has(kY) ? kY : kZ)],
                     "axis words without a motion mode (after G80)");
  }
  const Vec3 target = axisTarget(scan, st);
  if (st.next.motion == Motion::kRapid || st.next.motion == Motion::kLinear)
  {
    if (hasCentreOrRadius(scan))
    {
      throw ParseError(st.line, scan.column[firstCentreOrRadiusWord(scan)], "I/J/K/R words need G02 or G03");
    }
    moveStraight(scan, st, target);
  }
  else
  {
    if (st.machine_coordinates)
    {
      throw ParseError(st.line, st.motion_column ? st.motion_column : 1, "G53 with an arc");
    }
    moveArc(scan, st, target);
  }
}

void Parser::finishBlock(const Scan& scan, Step& st)
{
  if (scan.has(kL) && !st.l_used && st.block.call.kind == CallKind::kNone)
  {
    throw ParseError(st.line, scan.column[kL], "L (repeats) without a canned cycle or a subprogram call");
  }
  if (scan.has(kQ) && !st.next.canned_cycle && !st.q_used)
  {
    throw ParseError(st.line, scan.column[kQ], "Q without a canned cycle");
  }
  refuseUnusedWords(scan, st);
  if (st.block.program_end && st.next.cutter_comp != CutterComp::kOff)
  {
    // Ending with compensation on would leave the last offset move unfinished.
    compensationOff(st, true);
  }
}
}  // namespace gcode
}  // namespace cnc_bridge
