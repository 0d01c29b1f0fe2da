// The G-code parser: a single pass over each line's characters with no regex and no allocation
// once the block's move buffer has grown to the longest arc; numbers through std::from_chars
// (locale-independent, no exponent: 'E' is a word letter in G-code, not part of a number).
// A line is scanned into words (scanLine, through the BlockLexer of lexer.h), the words are applied to a copy of the
// modal state in the RS-274 order of execution (applyWords, gcode_words.cpp), and the motion they ask for becomes
// moves: straight (moveStraight), arcs cut into chords (moveArc), canned cycles (runCycle, gcode_cycles.cpp), G28/G30
// (referenceReturn). Cutter compensation offsets the moves (gcode_comp.cpp).
#include "cnc_bridge/gcode/gcode.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <sstream>

#include "cnc_bridge/gcode/lexer.h"
#include "gcode_internal.h"

namespace cnc_bridge
{
namespace gcode
{
namespace
{
ParseError wordError(uint32_t line, size_t index, const std::string& reason)
{
  return ParseError(line, static_cast<uint32_t>(index + 1), reason);
}

// The start of a line: its length bound, leading blanks, a tape marker ('%') or a block-delete
// slash. Returns false for a tape marker or a deleted block (block says which), else true with
// \p start at the first character of the words.
bool scanLineStart(std::string_view text, const ParserOptions& options, uint32_t line, Block& block, size_t& start)
{
  if (text.size() > options.max_line_length)
  {
    throw wordError(line, options.max_line_length,
                    "line longer than " + std::to_string(options.max_line_length) + " bytes");
  }
  const char* const data = text.data();
  const size_t size = text.size();
  size_t i = 0;
  while (i < size && isBlank(data[i]))
  {
    ++i;
  }
  if (i < size && data[i] == '%')
  {
    // A tape marker line; anything after '%' on it is a comment by convention.
    block.tape_marker = true;
    return false;
  }
  if (i < size && data[i] == '/')
  {
    if (options.block_delete)
    {
      block.deleted = true;
      return false;
    }
    ++i;
  }
  start = i;
  return true;
}

// G words are kept in tenths (G92.1 -> 921), several to a block.
void scanGWord(const LexedWord& word, uint32_t line, Scan& scan)
{
  const size_t letter_index = word.column - 1;
  if (scan.g_count == scan.g.size())
  {
    throw wordError(line, letter_index, "too many G words in one block");
  }
  const double tenths = word.value * 10.0;
  const double rounded = std::round(tenths);
  if (word.value < 0 || std::fabs(tenths - rounded) > 1e-6 || rounded > 10000)
  {
    throw wordError(line, letter_index, "malformed G number");
  }
  scan.g_column[scan.g_count] = static_cast<uint32_t>(letter_index + 1);
  scan.g[scan.g_count++] = static_cast<int>(rounded);
}

void scanMWord(const LexedWord& word, uint32_t line, Scan& scan)
{
  const size_t letter_index = word.column - 1;
  const double value = word.value;
  if (scan.m_count == scan.m.size())
  {
    throw wordError(line, letter_index, "more than 4 M words in one block");
  }
  if (value < 0 || value != std::floor(value) || value > 65535)
  {
    throw wordError(line, letter_index, "malformed M number");
  }
  scan.m_column[scan.m_count] = static_cast<uint32_t>(letter_index + 1);
  scan.m[scan.m_count++] = static_cast<uint16_t>(value);
}

// N (block number) and O (program number): whole numbers, kept in the block.
int64_t scanLabelWord(const LexedWord& word, uint32_t line, const char* what)
{
  const double value = word.value;
  if (value < 0 || value != std::floor(value) || value > 1e15)
  {
    throw wordError(line, word.column - 1, std::string("malformed ") + what);
  }
  return static_cast<int64_t>(value);
}

// The other letters: a Word of gcode_internal.h, at most once a block.
void scanValueWord(const LexedWord& word, uint32_t line, Scan& scan)
{
  const char letter = word.letter;
  const size_t letter_index = word.column - 1;
  const int w = wordIndex(letter);
  if (w < 0)
  {
    throw wordError(line, letter_index, std::string("word ") + letter + " is not supported");
  }
  if (scan.has(static_cast<Word>(w)))
  {
    throw wordError(line, letter_index, std::string("word ") + letter + " appears twice in one block");
  }
  scan.present |= 1u << w;
  if (word.decimal)
  {
    scan.decimal |= 1u << w;
  }
  scan.value[w] = word.value;
  scan.column[w] = static_cast<uint32_t>(letter_index + 1);
}

// Scans one line into words. Returns false for a tape marker or a deleted block (block says which).
bool scanLine(std::string_view text, const ParserOptions& options, uint32_t line, Scan& scan, Block& block)
{
  size_t start = 0;
  if (!scanLineStart(text, options, line, block, start))
  {
    return false;
  }
  BlockLexer lexer(text, BlockLexer::Mode::kStrict, line, start);
  LexedWord word;
  while (lexer.next(word))
  {
    block.has_words = true;
    switch (word.letter)
    {
      case 'G':
        scanGWord(word, line, scan);
        break;
      case 'M':
        scanMWord(word, line, scan);
        break;
      case 'N':
        block.block_number = scanLabelWord(word, line, "N block number");
        break;
      case 'O':
        block.program_number = scanLabelWord(word, line, "O program number");
        break;
      case 'A':
      case 'B':
      case 'C':
      case 'U':
      case 'V':
      case 'W':
        throw wordError(line, word.column - 1, std::string("axis ") + word.letter + " is not supported (X, Y, Z only)");
      default:
        scanValueWord(word, line, scan);
        break;
    }
  }
  return true;
}
}  // namespace

std::string gName(int tenths)
{
  std::string name = "G" + std::to_string(tenths / 10);
  if (tenths % 10)
  {
    name += "." + std::to_string(tenths % 10);
  }
  return name;
}

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

const char* toString(Dialect dialect)
{
  switch (dialect)
  {
    case Dialect::kHaas:
      return "haas";
    case Dialect::kFanuc:
      return "fanuc";
    case Dialect::kLinuxCnc:
      return "linuxcnc";
  }
  return "?";
}

Dialect parseDialect(const std::string& name)
{
  std::string lower;
  for (char c : name)
  {
    lower += static_cast<char>(c >= 'A' && c <= 'Z' ? c - 'A' + 'a' : c);
  }
  if (lower == "haas")
  {
    return Dialect::kHaas;
  }
  if (lower == "fanuc")
  {
    return Dialect::kFanuc;
  }
  if (lower == "linuxcnc")
  {
    return Dialect::kLinuxCnc;
  }
  throw ConfigError("G-code dialect \"" + name + "\" is not one of haas, fanuc, linuxcnc");
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

Parser::Parser(ParserOptions options) : options_(std::move(options))
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
  comp_ = std::make_shared<Comp>();
  comp_scratch_ = std::make_shared<Comp>();
}

double Parser::dwellSeconds(const Scan& scan, int word) const
{
  const double value = scan.value[word];
  const uint32_t column = scan.column[word];
  if (value < 0)
  {
    throw ParseError(line_, column, "negative dwell time");
  }
  switch (options_.dialect)
  {
    case Dialect::kHaas:
      // Haas: P with a decimal point is seconds (P1.5), without one milliseconds (P1500).
      return scan.hasDecimal(static_cast<Word>(word)) ? value : value / 1000.0;
    case Dialect::kFanuc:
      if (word == kX)
      {
        return value;  // G04 X: seconds
      }
      if (scan.hasDecimal(static_cast<Word>(word)))
      {
        throw ParseError(line_, column,
                         "a Fanuc dwell P is a whole number of milliseconds (P1500 = 1.5 s); write G04 X1.5 for "
                         "seconds, or choose the haas dialect");
      }
      return value / 1000.0;
    case Dialect::kLinuxCnc:
    default:
      return value;  // seconds
  }
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
  block.call = SubprogramCall();
  block.subprogram_end = false;

  Scan scan;
  if (!scanLine(text, options_, line, scan, block))
  {
    return block;
  }
  // Applied on a copy, so that an error changes nothing. Without a tool table G41/G42 are refused
  // and the compensation state stays as constructed, so it needs no copy (the parse rate).
  Comp* comp = comp_.get();
  if (options_.tool_table)
  {
    *comp_scratch_ = *comp_;
    comp = comp_scratch_.get();
  }
  Step step{block, state_, position_, *comp};
  step.line = line;
  try
  {
    applyWords(scan, step);
  }
  catch (...)
  {
    block.moves.clear();
    throw;
  }
  state_ = step.next;
  position_ = step.position;
  if (comp != comp_.get())
  {
    std::swap(comp_, comp_scratch_);
  }
  return block;
}

void Parser::emitRaw(Step& st, const Move& move)
{
  st.block.moves.push_back(move);
}

Move Parser::proto(const Step& st, Motion motion)
{
  Move m;
  m.motion = motion;
  m.start = st.position;
  m.end = st.position;
  m.feed_mm_per_min = st.next.feed_mm_per_min;
  m.spindle_rpm = st.next.spindle_rpm;
  m.spindle = st.next.spindle;
  m.tool = st.next.tool;
  m.coolant = st.next.coolant;
  m.line = st.line;
  m.block_number = st.block.block_number;
  return m;
}

void Parser::moveStraight(const Scan& /*scan*/, Step& st, const Vec3& target)
{
  Move m = proto(st, st.next.motion);
  m.end = target;
  m.machine_coordinates = st.machine_coordinates;
  // A G53 move is in another frame: equal numbers are no proof that the tool stays put.
  const bool report_anyway = st.machine_coordinates && options_.separate_machine_moves;
  const bool moves = target.x != st.position.x || target.y != st.position.y || target.z != st.position.z;
  if (st.machine_coordinates)
  {
    if (st.comp.on || st.next.cutter_comp != CutterComp::kOff)
    {
      throw ParseError(st.line, st.motion_column ? st.motion_column : 1,
                       "G53 with cutter compensation on: cancel it with G40 first");
    }
    if (report_anyway || moves)
    {
      emitRaw(st, m);
    }
    if (!options_.separate_machine_moves)
    {
      st.position = target;
    }
    return;
  }
  if (st.comp.on || st.comp_changed || st.next.cutter_comp != CutterComp::kOff)
  {
    compensatedStraight(st, m);
    return;
  }
  if (moves)
  {
    emitRaw(st, m);
  }
  st.position = target;
}

void Parser::referenceReturn(const Scan& scan, Step& st, bool g30)
{
  const uint32_t column = st.non_modal_column;
  if (st.comp.on || st.next.cutter_comp != CutterComp::kOff)
  {
    throw ParseError(st.line, column,
                     std::string(g30 ? "G30" : "G28") + " with cutter compensation on: cancel it with G40 first");
  }
  if (st.machine_coordinates)
  {
    throw ParseError(st.line, column, "G53 with G28/G30");
  }
  const Vec3& home = g30 ? options_.g30_position : options_.g28_position;
  const double scale = st.scale();
  bool named[3] = {scan.has(kX), scan.has(kY), scan.has(kZ)};
  if (!scan.hasAxis())
  {
    if (options_.dialect == Dialect::kFanuc)
    {
      return;  // Fanuc: only the named axes return; a bare G28 moves nothing
    }
    named[0] = named[1] = named[2] = true;  // Haas, LinuxCNC: every axis, straight to the point
  }
  else
  {
    // First to the intermediate point, given in program coordinates.
    Vec3 via = st.position;
    const Word axes[3] = {kX, kY, kZ};
    for (int a = 0; a < 3; ++a)
    {
      if (named[a])
      {
        const double v = scan.value[axes[a]] * scale;
        axis(via, a) =
            st.next.distance == DistanceMode::kIncremental ? axis(via, a) + v : v + axis(st.next.g92_offset, a);
      }
    }
    if (via.x != st.position.x || via.y != st.position.y || via.z != st.position.z)
    {
      Move m = proto(st, Motion::kRapid);
      m.end = via;
      emitRaw(st, m);
      st.position = via;
    }
  }
  // Then to the reference point, in machine coordinates, as a G53 move would be.
  Move m = proto(st, Motion::kRapid);
  for (int a = 0; a < 3; ++a)
  {
    if (named[a])
    {
      axis(m.end, a) = axis(home, a);
    }
  }
  m.machine_coordinates = true;
  m.reference_return = true;
  const bool moves = m.end.x != st.position.x || m.end.y != st.position.y || m.end.z != st.position.z;
  if (options_.separate_machine_moves || moves)
  {
    emitRaw(st, m);
  }
  if (!options_.separate_machine_moves)
  {
    st.position = m.end;
  }
}

Arc Parser::arcGeometry(const Scan& scan, const Step& st, const Vec3& start, const Vec3& target) const
{
  const uint32_t line = st.line;
  const double scale = st.scale();
  const PlaneAxes p = planeAxes(st.next.plane);
  const double su = axis(start, p.u), sv = axis(start, p.v);
  const double eu = axis(target, p.u), ev = axis(target, p.v);
  const bool cw = st.next.motion == Motion::kArcCw;
  double cu = 0.0, cv = 0.0;
  const uint32_t arc_column = st.motion_column ? st.motion_column : 1;
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
                       std::string("offset word not in the ") + toString(st.next.plane) + " plane of the arc");
    }
    if (!scan.has(static_cast<Word>(p.offset_u)) && !scan.has(static_cast<Word>(p.offset_v)))
    {
      throw ParseError(line, arc_column,
                       std::string("arc without I/J/K or R in the ") + toString(st.next.plane) + " plane");
    }
  }
  Arc arc;
  arc.p = p;
  arc.cu = cu;
  arc.cv = cv;
  arc.cw = cw;
  arc.start = start;
  arc.end = target;
  arc.rs = std::hypot(su - cu, sv - cv);
  arc.re = std::hypot(eu - cu, ev - cv);
  if (arc.rs < 1e-9)
  {
    throw ParseError(line, arc_column, "arc radius is zero");
  }
  if (std::fabs(arc.rs - arc.re) > std::max(options_.arc_radius_tolerance_mm, 0.001 * arc.rs))
  {
    std::ostringstream what;
    what << "arc end point is not on the circle (start radius " << arc.rs << " mm, end radius " << arc.re << " mm)";
    throw ParseError(line, arc_column, what.str());
  }
  arc.a0 = std::atan2(sv - cv, su - cu);
  const double a1 = std::atan2(ev - cv, eu - cu);
  const bool closed = std::fabs(eu - su) < 1e-9 && std::fabs(ev - sv) < 1e-9;
  arc.sweep = sweepBetween(arc.a0, a1, cw, closed);
  return arc;
}

double sweepBetween(double a0, double a1, bool cw, bool closed)
{
  if (closed)
  {
    return cw ? -2 * kPi : 2 * kPi;
  }
  double sweep = a1 - a0;
  if (cw)
  {
    while (sweep >= -1e-12)
    {
      sweep -= 2 * kPi;
    }
    if (sweep < -2 * kPi + 1e-12)
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
    if (sweep > 2 * kPi - 1e-12)
    {
      sweep -= 2 * kPi;
    }
  }
  return sweep;
}

void Parser::emitArc(Step& st, const Move& proto, const Arc& arc) const
{
  const PlaneAxes& p = arc.p;
  // Chord count from the sagitta: a chord spanning angle t deviates r (1 - cos(t/2)).
  const double r_max = std::max(arc.rs, arc.re);
  const double tol = options_.chord_tolerance_mm;
  const double max_step = tol >= r_max ? kPi : 2.0 * std::acos(1.0 - tol / r_max);
  double count = std::ceil(std::fabs(arc.sweep) / max_step - 1e-9);
  count = std::max(1.0, std::min(count, static_cast<double>(options_.max_arc_segments)));
  const uint32_t n = static_cast<uint32_t>(count);
  const double sw0 = axis(arc.start, p.w), sw1 = axis(arc.end, p.w);
  Vec3 prev = arc.start;
  for (uint32_t s = 1; s <= n; ++s)
  {
    Vec3 point;
    if (s == n)
    {
      point = arc.end;  // exactly the programmed end point, no accumulated rounding
    }
    else
    {
      const double f = static_cast<double>(s) / n;
      const double angle = arc.a0 + arc.sweep * f;
      const double radius = arc.rs + (arc.re - arc.rs) * f;  // a slight spiral if the radii differ
      axis(point, p.u) = arc.cu + radius * std::cos(angle);
      axis(point, p.v) = arc.cv + radius * std::sin(angle);
      axis(point, p.w) = sw0 + (sw1 - sw0) * f;
    }
    Move m = proto;
    m.motion = arc.cw ? Motion::kArcCw : Motion::kArcCcw;
    m.start = prev;
    m.end = point;
    m.segment = s - 1;
    m.segment_count = n;
    st.block.moves.push_back(m);
    prev = point;
  }
}

void Parser::moveArc(const Scan& scan, Step& st, const Vec3& target)
{
  const Arc arc = arcGeometry(scan, st, st.position, target);
  const Move m = proto(st, st.next.motion);
  if (st.comp.on || st.comp_changed || st.next.cutter_comp != CutterComp::kOff)
  {
    compensatedArc(st, m, arc);
    return;
  }
  emitArc(st, m, arc);
  st.position = target;
}

// ---------------------------------------------------------------------------------------------

namespace
{
constexpr size_t kChunkSize = size_t{64} * 1024;
// More O labels than this in one file is not a part program.
constexpr size_t kMaxLabels = 100000;

// The number of a line's leading O or N word ("O1000 (SUB)", " n100 G81 ..."), or -1.
int64_t leadingLabel(std::string_view line, char letter)
{
  size_t i = 0;
  while (i < line.size() && isBlank(line[i]))
  {
    ++i;
  }
  if (i < line.size() && line[i] == '/')
  {
    ++i;
  }
  if (i >= line.size() || (line[i] != letter && line[i] != letter - 'A' + 'a'))
  {
    return -1;
  }
  ++i;
  while (i < line.size() && isBlank(line[i]))
  {
    ++i;
  }
  int64_t value = 0;
  const auto result = std::from_chars(line.data() + i, line.data() + line.size(), value);
  if (result.ec != std::errc() || value < 0)
  {
    return -1;
  }
  return value;
}
}  // namespace

Reader::Reader(std::istream& in, const ParserOptions& options) : in_(in), parser_(options)
{
  buffer_.resize(std::max(kChunkSize, options.max_line_length + 2) * 2);
  const std::streampos start = in_.tellg();
  stream_start_ = start == std::streampos(-1) ? -1 : static_cast<int64_t>(start);
  in_.clear(in_.rdstate() & ~std::ios::failbit);
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
      line_offset_ = base_ + begin_;
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
      line_offset_ = base_ + begin_;
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
      base_ += begin_;
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

void Reader::jump(const Label& label)
{
  in_.clear();
  in_.seekg(static_cast<std::streamoff>(stream_start_ + static_cast<int64_t>(label.offset)));
  if (!in_)
  {
    throw Error("G-code input stream: cannot go back to byte " + std::to_string(label.offset) +
                " for a subprogram (the program must be a file)");
  }
  begin_ = end_ = 0;
  base_ = label.offset;
  eof_ = false;
  parser_.setNextLine(label.line);
}

Reader::Label Reader::findLabel(char letter, int64_t number, const Block& caller)
{
  auto& cache = letter == 'O' ? o_labels_ : n_labels_;
  for (const auto& entry : cache)
  {
    if (entry.first == number)
    {
      return entry.second;
    }
  }
  // Not seen yet: read the file from the start (subprograms usually follow the main program's
  // M30), noting every O label on the way.
  const Label back{base_ + begin_, caller.line + 1};
  jump(Label{0, 1});
  uint32_t line_number = 0;
  std::string_view line;
  std::optional<Label> found;
  while (nextLine(line))
  {
    ++line_number;
    const int64_t o = leadingLabel(line, 'O');
    if (o >= 0 && o_labels_.size() < kMaxLabels &&
        std::none_of(o_labels_.begin(), o_labels_.end(), [o](const auto& e) { return e.first == o; }))
    {
      o_labels_.emplace_back(o, Label{line_offset_, line_number});
    }
    if (!found && leadingLabel(line, letter) == number)
    {
      found = Label{line_offset_, line_number};
      if (letter == 'N')
      {
        n_labels_.emplace_back(number, *found);
        break;
      }
    }
  }
  if (!found)
  {
    jump(back);
    const std::string what = letter == 'O' ? "O" : "N";
    throw ParseError(caller.line, caller.call.column,
                     std::string(letter == 'O' ? "M98" : "M97") + " calls " + what + std::to_string(number) +
                         ", which is not in this program: add the subprogram (a line starting " + what +
                         std::to_string(number) + ", ending with M99) to the file");
  }
  return *found;
}

void Reader::call(const Block& block)
{
  const SubprogramCall& c = block.call;
  const char* code = c.kind == CallKind::kLocal ? "M97" : "M98";
  if (stream_start_ < 0)
  {
    throw ParseError(block.line, c.column,
                     std::string(code) + " needs a program that can be read again (a file), not a pipe");
  }
  if (calls_.size() >= parser_.options().max_call_depth)
  {
    throw ParseError(block.line, c.column,
                     std::string(code) + " P" + std::to_string(c.label) + ": subprograms nested deeper than " +
                         std::to_string(parser_.options().max_call_depth) + " (does a subprogram call itself?)");
  }
  if (c.repeats == 0)
  {
    return;
  }
  Frame frame;
  frame.return_offset = base_ + begin_;
  frame.return_line = block.line + 1;
  frame.remaining = c.repeats - 1;
  frame.target = findLabel(c.kind == CallKind::kLocal ? 'N' : 'O', c.label, block);
  calls_.push_back(frame);
  jump(frame.target);
}

const Block* Reader::nextBlock()
{
  for (;;)
  {
    if (ended_)
    {
      if (!flushed_)
      {
        flushed_ = true;
        tail_.line = parser_.lineCount();
        if (parser_.finish(tail_))
        {
          block_ = &tail_;
          move_index_ = 0;
          return block_;
        }
      }
      block_ = nullptr;
      return nullptr;
    }
    std::string_view line;
    if (!nextLine(line))
    {
      if (!calls_.empty())
      {
        throw ParseError(parser_.lineCount(), 1,
                         "the file ends inside a subprogram (line " + std::to_string(calls_.back().target.line) +
                             "): end it with M99");
      }
      ended_ = true;
      continue;
    }
    const uint64_t offset = line_offset_;
    if (!calls_.empty() && ++subprogram_blocks_ > parser_.options().max_subprogram_blocks)
    {
      throw ParseError(parser_.lineCount() + 1, 1,
                       "subprogram repeats run more than " + std::to_string(parser_.options().max_subprogram_blocks) +
                           " blocks: check the L counts of the M98/M97 calls");
    }
    const Block& block = parser_.parseLine(line);
    block_ = &block;
    move_index_ = 0;
    if (block.program_number >= 0 && o_labels_.size() < kMaxLabels)
    {
      const int64_t o = block.program_number;
      if (std::none_of(o_labels_.begin(), o_labels_.end(), [o](const auto& e) { return e.first == o; }))
      {
        o_labels_.emplace_back(o, Label{offset, block.line});
      }
    }
    // Where the next line comes from: the block's own moves are returned first.
    if (block.program_end)
    {
      ended_ = true;
    }
    else if (block.call.kind != CallKind::kNone)
    {
      call(block);
    }
    else if (block.subprogram_end)
    {
      if (calls_.empty())
      {
        ended_ = true;  // M99 in a main program loops on a control: here it ends the program
      }
      else
      {
        Frame& frame = calls_.back();
        if (frame.remaining > 0)
        {
          --frame.remaining;
          jump(frame.target);
        }
        else
        {
          const Label back{frame.return_offset, frame.return_line};
          calls_.pop_back();
          jump(back);
        }
      }
    }
    return block_;
  }
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
