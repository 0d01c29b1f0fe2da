// MacroProgram: parsing and running a small subset of Haas macro programs (see the header).
#include "dprnt_program.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/dprnt/format.h"

namespace cnc_bridge
{
namespace sim
{
namespace
{
// Recursive-descent evaluator over one block's text, starting at pos.
class Expression
{
 public:
  Expression(const std::string& text, size_t pos, MacroMachine& machine) : s_(text), pos_(pos), m_(machine) {}

  double parse() { return orExpr(); }
  size_t pos() const { return pos_; }
  /// #n or #[expr]: the variable number.
  int variableNumber()
  {
    expect('#');
    if (peek() == '[')
    {
      ++pos_;
      const double v = parse();
      expect(']');
      return static_cast<int>(std::lround(v));
    }
    return static_cast<int>(std::lround(number()));
  }

 private:
  char peek() const { return pos_ < s_.size() ? s_[pos_] : '\0'; }
  bool keyword(const char* word)
  {
    const size_t n = std::char_traits<char>::length(word);
    if (s_.compare(pos_, n, word) == 0)
    {
      pos_ += n;
      return true;
    }
    return false;
  }
  void expect(char c)
  {
    if (peek() != c)
      throw ConfigError(std::string("expected '") + c + "' at \"" + s_.substr(pos_, 12) + "\"");
    ++pos_;
  }
  double number()
  {
    const char* begin = s_.c_str() + pos_;
    char* end = nullptr;
    const double v = std::strtod(begin, &end);
    if (end == begin)
      throw ConfigError("expected a number at \"" + s_.substr(pos_, 12) + "\"");
    pos_ += static_cast<size_t>(end - begin);
    return v;
  }
  double orExpr()
  {
    double v = andExpr();
    while (keyword("OR"))
      v = (andExpr() != 0 || v != 0) ? 1 : 0;
    return v;
  }
  double andExpr()
  {
    double v = compare();
    while (keyword("AND"))
      v = (compare() != 0 && v != 0) ? 1 : 0;
    return v;
  }
  double compare()
  {
    const double a = sum();
    if (keyword("EQ"))
      return a == sum();
    if (keyword("NE"))
      return a != sum();
    if (keyword("GT"))
      return a > sum();
    if (keyword("GE"))
      return a >= sum();
    if (keyword("LT"))
      return a < sum();
    if (keyword("LE"))
      return a <= sum();
    return a;
  }
  double sum()
  {
    double v = product();
    for (;;)
    {
      if (peek() == '+')
        ++pos_, v += product();
      else if (peek() == '-')
        ++pos_, v -= product();
      else
        return v;
    }
  }
  double product()
  {
    double v = unary();
    for (;;)
    {
      if (peek() == '*')
        ++pos_, v *= unary();
      else if (peek() == '/')
      {
        ++pos_;
        const double d = unary();
        if (d == 0)
          throw ConfigError("division by zero");
        v /= d;
      }
      else
        return v;
    }
  }
  double unary()
  {
    if (peek() == '-')
      return ++pos_, -unary();
    if (peek() == '+')
      return ++pos_, unary();
    return primary();
  }
  double primary()
  {
    constexpr double kDeg = M_PI / 180.0;  // Haas trigonometry works in degrees
    if (peek() == '[')
    {
      ++pos_;
      const double v = parse();
      expect(']');
      return v;
    }
    if (peek() == '#')
    {
      const int n = variableNumber();
      const auto found = m_.variables.find(n);
      return found == m_.variables.end() ? 0.0 : found->second;
    }
    struct Function
    {
      const char* name;
      double (*apply)(double);
    };
    static const Function kFunctions[] = {
        {"ABS", [](double x) { return std::fabs(x); }},       {"SQRT", [](double x) { return std::sqrt(x); }},
        {"SIN", [](double x) { return std::sin(x * kDeg); }}, {"COS", [](double x) { return std::cos(x * kDeg); }},
        {"TAN", [](double x) { return std::tan(x * kDeg); }}, {"ROUND", [](double x) { return std::round(x); }},
        {"FIX", [](double x) { return std::floor(x); }},      {"FUP", [](double x) { return std::ceil(x); }},
    };
    for (const auto& f : kFunctions)
    {
      if (keyword(f.name))
      {
        expect('[');
        const double v = parse();
        expect(']');
        return f.apply(v);
      }
    }
    return number();
  }

  const std::string& s_;
  size_t pos_;
  MacroMachine& m_;
};

std::string upperNoSpaces(const std::string& text)
{
  std::string out;
  for (char c : text)
  {
    if (!std::isspace(static_cast<unsigned char>(c)))
      out.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(c))));
  }
  return out;
}

int loopLabel(const std::string& text, size_t pos)
{
  return std::atoi(text.c_str() + pos);
}
}  // namespace

MacroProgram MacroProgram::parse(const std::string& text)
{
  MacroProgram program;
  int line = 1;
  std::string current;
  int current_line = 1;
  int depth = 0;  // inside (comment)
  const auto flush = [&]
  {
    std::string block = current;
    current.clear();
    // DPRNT text keeps its spaces and case as written (the control prints them).
    const size_t dprnt = upperNoSpaces(block).find("DPRNT[");
    std::string compact;
    if (dprnt != std::string::npos)
    {
      const size_t at = [&]
      {
        for (size_t i = 0; i + 5 < block.size(); ++i)
          if (std::toupper(static_cast<unsigned char>(block[i])) == 'D' &&
              upperNoSpaces(block.substr(i, 6)) == "DPRNT[")
            return i;
        return std::string::npos;
      }();
      compact = upperNoSpaces(block.substr(0, at));
      const size_t open = block.find('[', at);
      const size_t close = block.rfind(']');
      if (close == std::string::npos || close < open)
        throw ConfigError("line " + std::to_string(current_line) + ": DPRNT without its closing ']'");
      compact += "DPRNT[" + block.substr(open + 1, close - open - 1) + "]";
    }
    else
    {
      compact = upperNoSpaces(block);
    }
    if (compact.empty() || compact[0] == '%' || compact[0] == 'O')
      return;
    Block b{compact, current_line};
    if (b.text[0] == 'N' && b.text.size() > 1 && std::isdigit(static_cast<unsigned char>(b.text[1])))
    {
      size_t i = 1;
      while (i < b.text.size() && std::isdigit(static_cast<unsigned char>(b.text[i])))
        ++i;
      b.n = std::atoi(b.text.c_str() + 1);
      b.text.erase(0, i);
      if (b.text.empty())
        return;
    }
    program.blocks_.push_back(b);
  };
  for (char c : text)
  {
    if (c == '(')
      ++depth;
    else if (c == ')' && depth > 0)
      --depth;
    else if (depth == 0 && (c == ';' || c == '\n'))
    {
      flush();
      current_line = line + (c == '\n');
    }
    else if (depth == 0 && c != '\r')
      current.push_back(c);
    if (c == '\n')
    {
      ++line;
      depth = 0;  // an unclosed comment ends with its line
    }
  }
  flush();
  return program;
}

namespace
{
ConfigError blockError(int line, const std::string& text, const std::string& what)
{
  return ConfigError("line " + std::to_string(line) + " (" + text + "): " + what);
}

// Address words: G, M, P, X, Y, Z ... each followed by a number, #var or [expr].
struct AddressWords
{
  bool probe = false, has_p = false, end = false;
  double p = 0;
  double target[3] = {0, 0, 0};
  bool has_axis[3] = {false, false, false};
};

AddressWords readAddressWords(const std::string& t, int line, MacroMachine& m)
{
  AddressWords w;
  size_t i = 0;
  while (i < t.size())
  {
    const char address = t[i];
    if (!std::isalpha(static_cast<unsigned char>(address)))
      throw blockError(line, t, std::string("unexpected '") + address + "'");
    Expression value(t, i + 1, m);
    const double v = value.parse();
    i = value.pos();
    switch (address)
    {
      case 'G':
        if (v == 90)
          m.incremental = false;
        else if (v == 91)
          m.incremental = true;
        else if (v == 65)
          w.probe = true;
        break;
      case 'M':
        w.end = w.end || v == 30 || v == 2 || v == 99;
        break;
      case 'P':
        w.has_p = true;
        w.p = v;
        break;
      case 'X':
      case 'Y':
      case 'Z':
        w.has_axis[address - 'X'] = true;
        w.target[address - 'X'] = v;
        break;
      default:
        break;  // feed, spindle, probe arguments (W, A, H ...): no effect here
    }
  }
  return w;
}

// Single-surface X/Y probe (WIPS, Renishaw Inspection Plus O9811 with X or Y): the probe moves
// from where it is toward the target until it touches a side of the part, and returns; the
// contact point is in #5061..#5063. Touching nothing is the control's alarm: an error here.
void probeSide(const AddressWords& w, const std::string& t, int line, MacroMachine& m)
{
  if (w.has_axis[0] == w.has_axis[1] || w.has_axis[2])
    throw blockError(line, t, "G65 P9811 here measures X or Y: give one of them");
  if (!m.side_contact)
    throw blockError(line, t, "the simulated part has no sides to touch (sim_haas_serial dprnt --part-corner)");
  const int axis = w.has_axis[0] ? 0 : 1;
  const double from[2] = {m.position[0], m.position[1]};
  double to[2] = {m.position[0], m.position[1]};
  to[axis] = m.incremental ? m.position[axis] + w.target[axis] : w.target[axis];
  double contact[2];
  if (!m.side_contact(from, to, contact))
    throw blockError(line, t, "the probe reached its target without touching the part (a real control alarms)");
  m.variables[5061] = contact[0];
  m.variables[5062] = contact[1];
  m.variables[5063] = m.position[2];
}

// A block of address words: a move, a probe cycle, the end. \returns false at M30/M02/M99.
bool runAddressBlock(const std::string& t, int line, MacroMachine& m)
{
  const AddressWords w = readAddressWords(t, line, m);
  if (!w.probe)
  {
    for (int axis = 0; axis < 3; ++axis)
    {
      if (w.has_axis[axis])
        m.position[axis] = m.incremental ? m.position[axis] + w.target[axis] : w.target[axis];
    }
  }
  if (w.probe && w.has_p && std::lround(w.p) == 9811)
    probeSide(w, t, line, m);
  if (w.probe && w.has_p && std::lround(w.p) == 9995)
  {
    // Single-surface Z probe (WIPS): the probe comes down at the current X Y and stops on the
    // surface; the G54 Z offset (#5223) becomes the surface height, as in OpenDNC's grid cycle.
    const double z = m.surface(m.position[0], m.position[1]);
    m.variables[5223] = z;
    m.variables[5061] = m.position[0];
    m.variables[5062] = m.position[1];
    m.variables[5063] = z;
  }
  // Work position (#5041-#5043) and machine position (#5021-#5023): work plus the G54
  // offset (#5221-#5223; the probe cycle above sets the Z offset, as in OpenDNC's).
  for (int axis = 0; axis < 3; ++axis)
  {
    m.variables[5041 + axis] = m.position[axis];
    const auto offset = m.variables.find(5221 + axis);
    m.variables[5021 + axis] = m.position[axis] + (offset == m.variables.end() ? 0.0 : offset->second);
  }
  return !w.end;
}
}  // namespace

std::function<bool(const double from[2], const double to[2], double contact[2])> rectangularPartSides(double corner_x,
                                                                                                      double corner_y,
                                                                                                      double yaw_rad)
{
  const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
  // The two faces: half-lines from the corner along the part's X (c, s) and its Y (-s, c).
  const double faces[2][2] = {{c, s}, {-s, c}};
  return [=](const double from[2], const double to[2], double contact[2])
  {
    const auto cross = [](double ax, double ay, double bx, double by) { return ax * by - ay * bx; };
    const double ex = to[0] - from[0], ey = to[1] - from[1];
    const double qx = corner_x - from[0], qy = corner_y - from[1];
    double first = 2.0;  // along the move, 0 at its start, 1 at its end
    for (const auto& d : faces)
    {
      const double denominator = cross(ex, ey, d[0], d[1]);
      if (denominator == 0.0)
        continue;  // the move runs along this face
      const double along_move = cross(qx, qy, d[0], d[1]) / denominator;
      const double along_face = cross(qx, qy, ex, ey) / denominator;
      if (along_move >= 0.0 && along_move <= 1.0 && along_face >= 0.0)
        first = std::min(first, along_move);
    }
    if (first > 1.0)
      return false;
    contact[0] = from[0] + first * ex;
    contact[1] = from[1] + first * ey;
    return true;
  };
}

bool MacroProgram::printBlock(const std::string& t, MacroMachine& m, const PrintFn& print)
{
  if (m.before_print)
    m.before_print(m);
  const std::string body = t.substr(6, t.size() - 7);
  const std::string line = dprnt::formatStatement(body,
                                                  [&](int n)
                                                  {
                                                    const auto found = m.variables.find(n);
                                                    return found == m.variables.end() ? 0.0 : found->second;
                                                  });
  return print(line);
}

size_t MacroProgram::whileBlock(size_t pc, MacroMachine& m) const
{
  const Block& b = blocks_[pc];
  const std::string& t = b.text;
  Expression cond(t, 5, m);
  const double v = cond.parse();
  if (t.compare(cond.pos(), 2, "DO") != 0)
    throw blockError(b.line, t, "WHILE without DOn");
  const int label = loopLabel(t, cond.pos() + 2);
  if (v != 0)
    return pc + 1;
  const std::string end = "END" + std::to_string(label);
  size_t j = pc + 1;
  while (j < blocks_.size() && blocks_[j].text != end)
    ++j;
  if (j == blocks_.size())
    throw blockError(b.line, t, "no " + end);
  return j + 1;
}

size_t MacroProgram::endBlock(size_t pc) const
{
  const Block& b = blocks_[pc];
  const std::string label = "DO" + b.text.substr(3);
  size_t j = pc;
  while (j > 0 && !(blocks_[j - 1].text.rfind("WHILE", 0) == 0 && blocks_[j - 1].text.size() >= label.size() &&
                    blocks_[j - 1].text.compare(blocks_[j - 1].text.size() - label.size(), label.size(), label) == 0))
    --j;
  if (j == 0)
    throw blockError(b.line, b.text, "END without its WHILE");
  return j - 1;
}

size_t MacroProgram::ifBlock(size_t pc, MacroMachine& m) const
{
  const Block& b = blocks_[pc];
  const std::string& t = b.text;
  Expression cond(t, 2, m);
  const double v = cond.parse();
  if (t.compare(cond.pos(), 4, "GOTO") != 0)
    throw blockError(b.line, t, "only IF [...] GOTOn is supported");
  if (v == 0)
    return pc + 1;
  const int target = loopLabel(t, cond.pos() + 4);
  size_t j = 0;
  while (j < blocks_.size() && blocks_[j].n != target)
    ++j;
  if (j == blocks_.size())
    throw blockError(b.line, t, "no block N" + std::to_string(target));
  return j;
}

size_t MacroProgram::step(size_t pc, MacroMachine& m, const PrintFn& print) const
{
  const Block& b = blocks_[pc];
  const std::string& t = b.text;
  if (t.rfind("DPRNT[", 0) == 0)
    return printBlock(t, m, print) ? pc + 1 : kStop;
  if (t[0] == '#')
  {
    Expression lhs(t, 0, m);
    const int n = lhs.variableNumber();
    if (lhs.pos() >= t.size() || t[lhs.pos()] != '=')
      throw blockError(b.line, t, "expected '=' after the variable");
    Expression rhs(t, lhs.pos() + 1, m);
    m.variables[n] = rhs.parse();
    return pc + 1;
  }
  if (t.rfind("WHILE", 0) == 0)
    return whileBlock(pc, m);
  if (t.rfind("END", 0) == 0)
    return endBlock(pc);
  if (t.rfind("IF", 0) == 0)
    return ifBlock(pc, m);
  return runAddressBlock(t, b.line, m) ? pc + 1 : kStop;
}

void MacroProgram::run(MacroMachine& m, const PrintFn& print) const
{
  size_t pc = 0;
  uint64_t steps = 0;
  while (pc < blocks_.size())
  {
    const Block& b = blocks_[pc];
    if (m.max_blocks > 0 && ++steps > m.max_blocks)
      throw blockError(b.line, b.text, "more than " + std::to_string(m.max_blocks) + " blocks: endless loop?");
    try
    {
      pc = step(pc, m, print);
    }
    catch (const ConfigError& e)
    {
      const std::string what = e.what();
      if (what.rfind("line ", 0) == 0)
        throw;
      throw blockError(b.line, b.text, what);
    }
    catch (const ProtocolError& e)  // a malformed DPRNT statement
    {
      throw blockError(b.line, b.text, e.what());
    }
  }
}
}  // namespace sim
}  // namespace cnc_bridge
