// MacroProgram: parsing and running a small subset of Haas macro programs (see the header).
#include "dprnt_program.h"

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

void MacroProgram::run(MacroMachine& m, const std::function<bool(const std::string&)>& print) const
{
  const auto error = [](const Block& b, const std::string& what)
  { return ConfigError("line " + std::to_string(b.line) + " (" + b.text + "): " + what); };
  size_t pc = 0;
  uint64_t steps = 0;
  while (pc < blocks_.size())
  {
    const Block& b = blocks_[pc];
    const std::string& t = b.text;
    if (m.max_blocks > 0 && ++steps > m.max_blocks)
      throw error(b, "more than " + std::to_string(m.max_blocks) + " blocks: endless loop?");
    size_t next = pc + 1;
    try
    {
      if (t.rfind("DPRNT[", 0) == 0)
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
        if (!print(line))
          return;
      }
      else if (t[0] == '#')
      {
        Expression lhs(t, 0, m);
        const int n = lhs.variableNumber();
        if (lhs.pos() >= t.size() || t[lhs.pos()] != '=')
          throw error(b, "expected '=' after the variable");
        Expression rhs(t, lhs.pos() + 1, m);
        m.variables[n] = rhs.parse();
      }
      else if (t.rfind("WHILE", 0) == 0)
      {
        Expression cond(t, 5, m);
        const double v = cond.parse();
        if (t.compare(cond.pos(), 2, "DO") != 0)
          throw error(b, "WHILE without DOn");
        const int label = loopLabel(t, cond.pos() + 2);
        if (v == 0)
        {
          const std::string end = "END" + std::to_string(label);
          size_t j = pc + 1;
          while (j < blocks_.size() && blocks_[j].text != end)
            ++j;
          if (j == blocks_.size())
            throw error(b, "no " + end);
          next = j + 1;
        }
      }
      else if (t.rfind("END", 0) == 0)
      {
        const std::string label = "DO" + t.substr(3);
        size_t j = pc;
        while (j > 0 &&
               !(blocks_[j - 1].text.rfind("WHILE", 0) == 0 && blocks_[j - 1].text.size() >= label.size() &&
                 blocks_[j - 1].text.compare(blocks_[j - 1].text.size() - label.size(), label.size(), label) == 0))
          --j;
        if (j == 0)
          throw error(b, "END without its WHILE");
        next = j - 1;
      }
      else if (t.rfind("IF", 0) == 0)
      {
        Expression cond(t, 2, m);
        const double v = cond.parse();
        if (t.compare(cond.pos(), 4, "GOTO") != 0)
          throw error(b, "only IF [...] GOTOn is supported");
        if (v != 0)
        {
          const int target = loopLabel(t, cond.pos() + 4);
          size_t j = 0;
          while (j < blocks_.size() && blocks_[j].n != target)
            ++j;
          if (j == blocks_.size())
            throw error(b, "no block N" + std::to_string(target));
          next = j;
        }
      }
      else
      {
        // Address words: G, M, P, X, Y, Z ... each followed by a number, #var or [expr].
        bool probe = false, has_p = false, end = false;
        double p = 0;
        double target[3];
        bool has_axis[3] = {false, false, false};
        size_t i = 0;
        while (i < t.size())
        {
          const char address = t[i];
          if (!std::isalpha(static_cast<unsigned char>(address)))
            throw error(b, std::string("unexpected '") + address + "'");
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
                probe = true;
              break;
            case 'M':
              end = end || v == 30 || v == 2 || v == 99;
              break;
            case 'P':
              has_p = true;
              p = v;
              break;
            case 'X':
            case 'Y':
            case 'Z':
              has_axis[address - 'X'] = true;
              target[address - 'X'] = v;
              break;
            default:
              break;  // feed, spindle, probe arguments (W, A, H ...): no effect here
          }
        }
        if (!probe)
        {
          for (int axis = 0; axis < 3; ++axis)
          {
            if (has_axis[axis])
              m.position[axis] = m.incremental ? m.position[axis] + target[axis] : target[axis];
          }
        }
        if (probe && has_p && std::lround(p) == 9995)
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
        if (end)
          return;
      }
    }
    catch (const ConfigError& e)
    {
      const std::string what = e.what();
      if (what.rfind("line ", 0) == 0)
        throw;
      throw error(b, what);
    }
    catch (const ProtocolError& e)  // a malformed DPRNT statement
    {
      throw error(b, e.what());
    }
    pc = next;
  }
}
}  // namespace sim
}  // namespace cnc_bridge
