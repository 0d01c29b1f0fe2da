// The G-code parser: a single pass over each line's characters with no regex and no allocation
// once the block's move buffer has grown to the longest arc; numbers through std::from_chars
// (locale-independent, no exponent: 'E' is a word letter in G-code, not part of a number).
#include "cnc_bridge/gcode/gcode.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <sstream>

namespace cnc_bridge
{
namespace gcode
{
namespace
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
  kWordCount
};

int wordIndex(char letter)
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
    default:
      return -1;
  }
}

double& axis(Vec3& v, int i)
{
  return i == 0 ? v.x : (i == 1 ? v.y : v.z);
}

// (u, v, normal) axis indices of each plane, and the centre-offset words along u and v.
struct PlaneAxes
{
  int u, v, w;
  int offset_u, offset_v;
};
PlaneAxes planeAxes(Plane plane)
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

std::string describeChar(char c)
{
  const auto byte = static_cast<unsigned char>(c);
  if (byte >= 32 && byte < 127)
  {
    return std::string("'") + c + "'";
  }
  static const char kHex[] = "0123456789abcdef";
  return std::string("byte 0x") + kHex[byte >> 4] + kHex[byte & 15];
}

inline bool isSpace(char c)
{
  return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v';
}

// The words of one line as scanned, before they are applied.
struct Scan
{
  double value[kWordCount];
  uint32_t column[kWordCount];
  uint16_t present = 0;  // bit per Word
  // G codes in tenths (G91.1 -> 911) with their columns.
  std::array<int, 8> g{};
  std::array<uint32_t, 8> g_column{};
  uint8_t g_count = 0;
  std::array<uint16_t, Block::kMaxMCodes> m{};
  std::array<uint32_t, Block::kMaxMCodes> m_column{};
  uint8_t m_count = 0;
  bool has(Word w) const { return present & (1u << w); }
};
}  // namespace

const char* toString(Motion motion)
{
  switch (motion)
  {
    case Motion::kNone:
      return "none";
    case Motion::kRapid:
      return "rapid";
    case Motion::kLinear:
      return "linear";
    case Motion::kArcCw:
      return "arc-cw";
    case Motion::kArcCcw:
      return "arc-ccw";
  }
  return "?";
}

const char* toString(Plane plane)
{
  switch (plane)
  {
    case Plane::kXY:
      return "XY";
    case Plane::kZX:
      return "ZX";
    case Plane::kYZ:
      return "YZ";
  }
  return "?";
}

static std::string formatParseError(uint32_t line, uint32_t column, const std::string& reason)
{
  std::ostringstream out;
  out << "G-code line " << line << ", column " << column << ": " << reason;
  return out.str();
}

ParseError::ParseError(uint32_t line, uint32_t column, const std::string& reason)
    : ProtocolError(formatParseError(line, column, reason)), line_(line), column_(column), reason_(reason)
{
}

void Bounds::add(const Vec3& p)
{
  min.x = std::min(min.x, p.x);
  min.y = std::min(min.y, p.y);
  min.z = std::min(min.z, p.z);
  max.x = std::max(max.x, p.x);
  max.y = std::max(max.y, p.y);
  max.z = std::max(max.z, p.z);
}

Parser::Parser(const ParserOptions& options) : options_(options)
{
  if (!(options_.chord_tolerance_mm > 0.0) || !std::isfinite(options_.chord_tolerance_mm))
  {
    throw ConfigError("G-code chord tolerance must be a positive number of millimetres");
  }
  if (options_.max_arc_segments < 1)
  {
    throw ConfigError("G-code max_arc_segments must be at least 1");
  }
  reset();
}

void Parser::reset()
{
  state_ = ModalState();
  state_.units = options_.initial_units;
  state_.motion = options_.initial_motion;
  position_ = options_.initial_position;
  line_ = 0;
  block_.moves.clear();
}

const Block& Parser::parseLine(std::string_view text)
{
  ++line_;
  const uint32_t line = line_;
  Block& block = block_;
  block.line = line;
  block.block_number = -1;
  block.program_number = -1;
  block.tape_marker = false;
  block.deleted = false;
  block.has_words = false;
  block.m_count = 0;
  block.tool_change = false;
  block.program_stop = false;
  block.program_end = false;
  block.dwell_s = -1.0;
  block.moves.clear();

  auto fail = [line](size_t index, const std::string& reason) -> ParseError
  { return ParseError(line, static_cast<uint32_t>(index + 1), reason); };

  if (text.size() > options_.max_line_length)
  {
    throw fail(options_.max_line_length, "line longer than " + std::to_string(options_.max_line_length) + " bytes");
  }

  // ---- Scan: letters and numbers into Scan, comments skipped. ----
  Scan scan;
  const char* const data = text.data();
  const size_t size = text.size();
  size_t i = 0;
  while (i < size && isSpace(data[i]))
  {
    ++i;
  }
  if (i < size && data[i] == '%')
  {
    // A tape marker line; anything after '%' on it is a comment by convention.
    block.tape_marker = true;
    return block;
  }
  if (i < size && data[i] == '/')
  {
    if (options_.block_delete)
    {
      block.deleted = true;
      return block;
    }
    ++i;
  }

  while (i < size)
  {
    const char c = data[i];
    if (isSpace(c))
    {
      ++i;
      continue;
    }
    if (c == '(')
    {
      const size_t open = i;
      ++i;
      while (i < size && data[i] != ')')
      {
        if (data[i] == '(')
        {
          throw fail(i, "nested '(' inside a comment");
        }
        ++i;
      }
      if (i >= size)
      {
        throw fail(open, "comment '(' not closed on this line");
      }
      ++i;
      continue;
    }
    if (c == ';')
    {
      break;
    }
    if (c == '#' || c == '[' || c == '=')
    {
      throw fail(i, std::string("macro expressions ('") + c + "') are not supported");
    }
    char letter = c;
    if (letter >= 'a' && letter <= 'z')
    {
      letter = static_cast<char>(letter - 'a' + 'A');
    }
    if (letter < 'A' || letter > 'Z')
    {
      throw fail(i, "unexpected character " + describeChar(c));
    }
    const size_t letter_index = i;
    ++i;
    while (i < size && isSpace(data[i]))
    {
      ++i;
    }
    // Number: optional sign, digits with at most one '.', no exponent.
    bool negative = false;
    if (i < size && (data[i] == '+' || data[i] == '-'))
    {
      negative = data[i] == '-';
      ++i;
    }
    const size_t number_start = i;
    double value = 0.0;
    if (i < size && data[i] == '.' && (i + 1 >= size || data[i + 1] < '0' || data[i + 1] > '9'))
    {
      throw fail(letter_index, std::string("word ") + letter + " has no number");
    }
    auto result = std::from_chars(data + i, data + size, value, std::chars_format::fixed);
    if (result.ec != std::errc() || result.ptr == data + number_start)
    {
      throw fail(letter_index, std::string("word ") + letter + " has no number");
    }
    i = static_cast<size_t>(result.ptr - data);
    if (negative)
    {
      value = -value;
    }
    if (!std::isfinite(value))
    {
      throw fail(letter_index, std::string("word ") + letter + " number out of range");
    }
    block.has_words = true;

    switch (letter)
    {
      case 'G':
      {
        if (scan.g_count == scan.g.size())
        {
          throw fail(letter_index, "too many G words in one block");
        }
        const double tenths = value * 10.0;
        const double rounded = std::round(tenths);
        if (value < 0 || std::fabs(tenths - rounded) > 1e-6 || rounded > 10000)
        {
          throw fail(letter_index, "malformed G number");
        }
        scan.g_column[scan.g_count] = static_cast<uint32_t>(letter_index + 1);
        scan.g[scan.g_count++] = static_cast<int>(rounded);
        break;
      }
      case 'M':
      {
        if (scan.m_count == scan.m.size())
        {
          throw fail(letter_index, "more than 4 M words in one block");
        }
        if (value < 0 || value != std::floor(value) || value > 65535)
        {
          throw fail(letter_index, "malformed M number");
        }
        scan.m_column[scan.m_count] = static_cast<uint32_t>(letter_index + 1);
        scan.m[scan.m_count++] = static_cast<uint16_t>(value);
        break;
      }
      case 'N':
        if (value < 0 || value != std::floor(value) || value > 1e15)
        {
          throw fail(letter_index, "malformed N block number");
        }
        block.block_number = static_cast<int64_t>(value);
        break;
      case 'O':
        if (value < 0 || value != std::floor(value) || value > 1e15)
        {
          throw fail(letter_index, "malformed O program number");
        }
        block.program_number = static_cast<int64_t>(value);
        break;
      case 'A':
      case 'B':
      case 'C':
      case 'U':
      case 'V':
      case 'W':
        throw fail(letter_index, std::string("axis ") + letter + " is not supported (X, Y, Z only)");
      default:
      {
        const int w = wordIndex(letter);
        if (w < 0)
        {
          throw fail(letter_index, std::string("word ") + letter + " is not supported");
        }
        if (scan.present & (1u << w))
        {
          throw fail(letter_index, std::string("word ") + letter + " appears twice in one block");
        }
        scan.present |= static_cast<uint16_t>(1u << w);
        scan.value[w] = value;
        scan.column[w] = static_cast<uint32_t>(letter_index + 1);
        break;
      }
    }
  }

  // ---- Apply, in the RS-274 order of execution, on a copy so that an error changes nothing. ----
  ModalState next = state_;
  bool motion_word = false;
  bool machine_coordinates = false;
  bool dwell = false;
  int motion_column = 0;
  bool seen_group[4] = {false, false, false, false};  // motion, plane, units, distance
  auto group = [&](int g, uint32_t column)
  {
    if (seen_group[g])
    {
      throw ParseError(line, column, "two G codes of the same modal group in one block");
    }
    seen_group[g] = true;
  };
  for (uint8_t k = 0; k < scan.g_count; ++k)
  {
    const uint32_t column = scan.g_column[k];
    switch (scan.g[k])
    {
      case 0:
        group(0, column);
        next.motion = Motion::kRapid;
        motion_word = true;
        motion_column = column;
        break;
      case 10:
        group(0, column);
        next.motion = Motion::kLinear;
        motion_word = true;
        motion_column = column;
        break;
      case 20:
        group(0, column);
        next.motion = Motion::kArcCw;
        motion_word = true;
        motion_column = column;
        break;
      case 30:
        group(0, column);
        next.motion = Motion::kArcCcw;
        motion_word = true;
        motion_column = column;
        break;
      case 800:
        group(0, column);
        next.motion = Motion::kNone;
        break;
      case 40:
        dwell = true;
        break;
      case 170:
        group(1, column);
        next.plane = Plane::kXY;
        break;
      case 180:
        group(1, column);
        next.plane = Plane::kZX;
        break;
      case 190:
        group(1, column);
        next.plane = Plane::kYZ;
        break;
      case 200:
        group(2, column);
        next.units = Units::kInches;
        break;
      case 210:
        group(2, column);
        next.units = Units::kMillimetres;
        break;
      case 900:
        group(3, column);
        next.distance = DistanceMode::kAbsolute;
        break;
      case 910:
        group(3, column);
        next.distance = DistanceMode::kIncremental;
        break;
      case 530:
        machine_coordinates = true;
        break;
      // Accepted without effect on the programmed geometry: cutter compensation off (G40), tool
      // length offset (G43/G49: the offset values are in the control), work offsets (G54..G59:
      // likewise), feed per minute (G94, the only feed mode we support).
      case 400:
      case 430:
      case 490:
      case 540:
      case 550:
      case 560:
      case 570:
      case 580:
      case 590:
      case 940:
        break;
      default:
      {
        std::ostringstream what;
        what << "G" << scan.g[k] / 10;
        if (scan.g[k] % 10)
        {
          what << "." << scan.g[k] % 10;
        }
        what << " is not supported";
        throw ParseError(line, column, what.str());
      }
    }
  }

  const double scale = next.units == Units::kInches ? kMmPerInch : 1.0;
  if (scan.has(kF))
  {
    if (scan.value[kF] < 0)
    {
      throw ParseError(line, scan.column[kF], "negative feed rate");
    }
    next.feed_mm_per_min = scan.value[kF] * scale;
  }
  if (scan.has(kS))
  {
    if (scan.value[kS] < 0)
    {
      throw ParseError(line, scan.column[kS], "negative spindle speed");
    }
    next.spindle_rpm = scan.value[kS];
  }
  if (scan.has(kT))
  {
    if (scan.value[kT] < 0 || scan.value[kT] != std::floor(scan.value[kT]) || scan.value[kT] > 1e9)
    {
      throw ParseError(line, scan.column[kT], "malformed T tool number");
    }
    next.selected_tool = static_cast<int32_t>(scan.value[kT]);
  }
  for (uint8_t k = 0; k < scan.m_count; ++k)
  {
    block.m_codes[block.m_count++] = scan.m[k];
    switch (scan.m[k])
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
      default:
        break;  // machine-specific: reported in m_codes
    }
  }
  if (dwell)
  {
    if (!scan.has(kP) || scan.value[kP] < 0)
    {
      throw fail(0, "G04 needs a P word (dwell seconds)");
    }
    block.dwell_s = scan.value[kP];
  }

  const bool has_axis = scan.has(kX) || scan.has(kY) || scan.has(kZ);
  const bool has_offset = scan.has(kI) || scan.has(kJ) || scan.has(kK) || scan.has(kR);
  if (dwell && has_axis)
  {
    throw fail(0, "G04 with axis words");
  }
  Vec3 start = position_;
  if (has_axis && !dwell)
  {
    if (next.motion == Motion::kNone)
    {
      throw ParseError(line, scan.column[scan.has(kX) ? kX : (scan.has(kY) ? kY : kZ)],
                       "axis words without a motion mode (after G80)");
    }
    Vec3 target = start;
    const Word axes[3] = {kX, kY, kZ};
    for (int a = 0; a < 3; ++a)
    {
      if (scan.has(axes[a]))
      {
        const double v = scan.value[axes[a]] * scale;
        if (next.distance == DistanceMode::kIncremental && !machine_coordinates)
        {
          axis(target, a) += v;
        }
        else
        {
          axis(target, a) = v;
        }
      }
    }
    Move proto;
    proto.motion = next.motion;
    proto.start = start;
    proto.end = target;
    proto.feed_mm_per_min = next.feed_mm_per_min;
    proto.spindle_rpm = next.spindle_rpm;
    proto.spindle = next.spindle;
    proto.tool = next.tool;
    proto.coolant = next.coolant;
    proto.machine_coordinates = machine_coordinates;
    proto.line = line;
    proto.block_number = block.block_number;

    if (next.motion == Motion::kRapid || next.motion == Motion::kLinear)
    {
      if (has_offset)
      {
        const Word w = scan.has(kI) ? kI : (scan.has(kJ) ? kJ : (scan.has(kK) ? kK : kR));
        throw ParseError(line, scan.column[w], "I/J/K/R words need G02 or G03");
      }
      // A G53 move is in another frame: equal numbers are no proof that the tool stays put.
      const bool report_anyway = machine_coordinates && options_.separate_machine_moves;
      if (report_anyway || target.x != start.x || target.y != start.y || target.z != start.z)
      {
        block.moves.push_back(proto);
      }
    }
    else
    {
      if (machine_coordinates)
      {
        throw ParseError(line, static_cast<uint32_t>(motion_column ? motion_column : 1), "G53 with an arc");
      }
      const PlaneAxes p = planeAxes(next.plane);
      const double su = axis(start, p.u), sv = axis(start, p.v);
      const double eu = axis(target, p.u), ev = axis(target, p.v);
      const bool cw = next.motion == Motion::kArcCw;
      double cu = 0.0, cv = 0.0;
      double sweep = 0.0;
      const uint32_t arc_column = static_cast<uint32_t>(motion_column ? motion_column : 1);
      if (scan.has(kR))
      {
        // Another plane's offset word next to R is ambiguous: reject rather than guess.
        if (scan.has(kI) || scan.has(kJ) || scan.has(kK))
        {
          throw ParseError(line, scan.column[kR], "arc with both R and I/J/K");
        }
        const double r = scan.value[kR] * scale;
        const double du = eu - su, dv = ev - sv;
        const double d = std::hypot(du, dv);
        if (d < 1e-9)
        {
          throw ParseError(line, scan.column[kR], "R-form arc with end point equal to start point");
        }
        const double radius = std::fabs(r);
        if (radius < 1e-9)
        {
          throw ParseError(line, scan.column[kR], "arc radius R is zero");
        }
        double h2 = radius * radius - d * d / 4.0;
        if (h2 < 0)
        {
          if (d / 2.0 - radius > options_.arc_radius_tolerance_mm)
          {
            throw ParseError(line, scan.column[kR], "arc radius R is smaller than half the distance to the end point");
          }
          h2 = 0;
        }
        const double h = std::sqrt(h2);
        // Going counter-clockwise round a centre, the centre is on the left of the chord; a
        // clockwise arc has it on the right. Negative R (the long way round) swaps sides.
        double side = cw ? -1.0 : 1.0;
        if (r < 0)
        {
          side = -side;
        }
        const double mu = (su + eu) / 2.0, mv = (sv + ev) / 2.0;
        cu = mu + side * h * (-dv / d);
        cv = mv + side * h * (du / d);
      }
      else
      {
        cu = su + (scan.has(static_cast<Word>(p.offset_u)) ? scan.value[p.offset_u] * scale : 0.0);
        cv = sv + (scan.has(static_cast<Word>(p.offset_v)) ? scan.value[p.offset_v] * scale : 0.0);
        // The offset word along the normal axis makes no sense in this plane.
        const int normal_offset = kI + p.w;
        if (scan.has(static_cast<Word>(normal_offset)))
        {
          throw ParseError(line, scan.column[normal_offset],
                           std::string("offset word not in the ") + toString(next.plane) + " plane of the arc");
        }
        if (!scan.has(static_cast<Word>(p.offset_u)) && !scan.has(static_cast<Word>(p.offset_v)))
        {
          throw ParseError(line, arc_column,
                           std::string("arc without I/J/K or R in the ") + toString(next.plane) + " plane");
        }
      }
      const double rs = std::hypot(su - cu, sv - cv);
      const double re = std::hypot(eu - cu, ev - cv);
      if (rs < 1e-9)
      {
        throw ParseError(line, arc_column, "arc radius is zero");
      }
      if (std::fabs(rs - re) > std::max(options_.arc_radius_tolerance_mm, 0.001 * rs))
      {
        std::ostringstream what;
        what << "arc end point is not on the circle (start radius " << rs << " mm, end radius " << re << " mm)";
        throw ParseError(line, arc_column, what.str());
      }
      const double a0 = std::atan2(sv - cv, su - cu);
      const double a1 = std::atan2(ev - cv, eu - cu);
      sweep = a1 - a0;
      const bool closed = std::fabs(eu - su) < 1e-9 && std::fabs(ev - sv) < 1e-9;
      if (cw)
      {
        while (sweep >= -1e-12)
        {
          sweep -= 2 * kPi;
        }
        if (!closed && sweep < -2 * kPi + 1e-12)
        {
          sweep += 2 * kPi;
        }
      }
      else
      {
        while (sweep <= 1e-12)
        {
          sweep += 2 * kPi;
        }
        if (!closed && sweep > 2 * kPi - 1e-12)
        {
          sweep -= 2 * kPi;
        }
      }
      if (closed)
      {
        sweep = cw ? -2 * kPi : 2 * kPi;
      }
      // Chord count from the sagitta: a chord spanning angle t deviates r (1 - cos(t/2)).
      const double r_max = std::max(rs, re);
      const double tol = options_.chord_tolerance_mm;
      const double max_step = tol >= r_max ? kPi : 2.0 * std::acos(1.0 - tol / r_max);
      double count = std::ceil(std::fabs(sweep) / max_step - 1e-9);
      count = std::max(1.0, std::min(count, static_cast<double>(options_.max_arc_segments)));
      const uint32_t n = static_cast<uint32_t>(count);
      const double sw0 = axis(start, p.w), sw1 = axis(target, p.w);
      Vec3 prev = start;
      for (uint32_t s = 1; s <= n; ++s)
      {
        Vec3 point;
        if (s == n)
        {
          point = target;  // exactly the programmed end point, no accumulated rounding
        }
        else
        {
          const double f = static_cast<double>(s) / n;
          const double angle = a0 + sweep * f;
          const double radius = rs + (re - rs) * f;  // a slight spiral if the radii differ
          axis(point, p.u) = cu + radius * std::cos(angle);
          axis(point, p.v) = cv + radius * std::sin(angle);
          axis(point, p.w) = sw0 + (sw1 - sw0) * f;
        }
        Move m = proto;
        m.start = prev;
        m.end = point;
        m.segment = s - 1;
        m.segment_count = n;
        block.moves.push_back(m);
        prev = point;
      }
      position_ = target;
    }
    if (!(machine_coordinates && options_.separate_machine_moves))
    {
      position_ = target;
    }
  }
  else if (has_offset)
  {
    const Word w = scan.has(kI) ? kI : (scan.has(kJ) ? kJ : (scan.has(kK) ? kK : kR));
    if (motion_word && (next.motion == Motion::kArcCw || next.motion == Motion::kArcCcw))
    {
      throw ParseError(line, scan.column[w], "arc without an end point (X/Y/Z)");
    }
    throw ParseError(line, scan.column[w], "I/J/K/R words without an arc");
  }
  state_ = next;
  return block;
}

// ---------------------------------------------------------------------------------------------

namespace
{
constexpr size_t kChunkSize = 64 * 1024;
}

Reader::Reader(std::istream& in, const ParserOptions& options) : in_(in), parser_(options)
{
  buffer_.resize(std::max(kChunkSize, options.max_line_length + 2) * 2);
}

bool Reader::nextLine(std::string_view& line)
{
  for (;;)
  {
    const char* begin = buffer_.data() + begin_;
    const void* nl = std::memchr(begin, '\n', end_ - begin_);
    if (nl)
    {
      const size_t length = static_cast<const char*>(nl) - begin;
      line = std::string_view(begin, length);
      begin_ += length + 1;
      return true;
    }
    if (eof_)
    {
      if (begin_ == end_)
      {
        return false;
      }
      line = std::string_view(begin, end_ - begin_);
      begin_ = end_;
      return true;
    }
    // Keep the partial line at the front, then fill the rest of the buffer.
    const size_t pending = end_ - begin_;
    if (pending > parser_.options().max_line_length + 1)
    {
      // Report it as the parser would, at the line it would have been.
      throw ParseError(parser_.lineCount() + 1, static_cast<uint32_t>(parser_.options().max_line_length + 1),
                       "line longer than " + std::to_string(parser_.options().max_line_length) + " bytes");
    }
    if (begin_ > 0)
    {
      std::memmove(buffer_.data(), begin, pending);
      begin_ = 0;
      end_ = pending;
    }
    in_.read(buffer_.data() + end_, static_cast<std::streamsize>(buffer_.size() - end_));
    const size_t got = static_cast<size_t>(in_.gcount());
    end_ += got;
    if (got == 0 || in_.eof())
    {
      if (in_.bad())
      {
        throw Error("G-code input stream failed");
      }
      eof_ = in_.eof() || got == 0;
    }
  }
}

const Block* Reader::nextBlock()
{
  std::string_view line;
  if (!nextLine(line))
  {
    block_ = nullptr;
    return nullptr;
  }
  block_ = &parser_.parseLine(line);
  move_index_ = 0;
  return block_;
}

bool Reader::nextMove(Move& move)
{
  while (!block_ || move_index_ >= block_->moves.size())
  {
    if (!nextBlock())
    {
      return false;
    }
  }
  move = block_->moves[move_index_++];
  return true;
}

}  // namespace gcode
}  // namespace cnc_bridge
