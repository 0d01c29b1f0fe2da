// Haas DPRNT number and statement formatting (rules in the header).
#include "cnc_bridge/dprnt/format.h"

#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>

#include "cnc_bridge/common/error.h"

namespace cnc_bridge
{
namespace dprnt
{
std::string formatValue(double value, int whole, int fraction)
{
  if (whole < 0 || fraction < 0 || whole + fraction < 1 || whole + fraction > 8)
  {
    throw ConfigError("DPRNT format [" + std::to_string(whole) + std::to_string(fraction) +
                      "]: whole + fraction places must be 1..8");
  }
  if (!std::isfinite(value))
  {
    // A control never holds one; an empty variable (#0) prints as zero on Haas.
    value = 0.0;
  }
  static constexpr double kPow10[] = {1, 10, 100, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8};
  // std::round rounds half away from zero; scaling first makes 0.0125 at 3 places 12.5 -> 13
  // as on the control, where printf("%.3f") would see the binary 0.01249999... and print 0.012.
  // With f = 0 the manual's own example prints T 1 for 1.5436: the whole part, fraction dropped.
  const double scaled = fraction == 0 ? std::trunc(std::fabs(value)) : std::round(std::fabs(value) * kPow10[fraction]);
  const bool negative = value < 0 && scaled > 0;
  char digits[48];
  if (fraction == 0)
  {
    std::snprintf(digits, sizeof digits, "%s%.0f", negative ? "-" : "", scaled);
  }
  else
  {
    const double int_part = std::floor(scaled / kPow10[fraction]);
    const double frac_part = scaled - int_part * kPow10[fraction];
    std::snprintf(digits, sizeof digits, "%s%.0f.%0*.0f", negative ? "-" : "", int_part, fraction, frac_part);
  }
  std::string text(digits);
  const size_t point = text.find('.');
  const size_t whole_len = point == std::string::npos ? text.size() : point;
  if (whole_len < static_cast<size_t>(whole))
  {
    text.insert(0, static_cast<size_t>(whole) - whole_len, ' ');
  }
  return text;
}

std::string formatStatement(std::string_view body, const std::function<double(int)>& lookup)
{
  std::string out;
  out.reserve(body.size() + 16);
  size_t i = 0;
  while (i < body.size())
  {
    const char c = body[i];
    if (c == '*')
    {
      out.push_back(' ');
      ++i;
      continue;
    }
    if (c != '#')
    {
      out.push_back(c);
      ++i;
      continue;
    }
    // #nnnn[wf]
    size_t j = i + 1;
    int variable = 0;
    while (j < body.size() && std::isdigit(static_cast<unsigned char>(body[j])) && j - i <= 5)
    {
      variable = variable * 10 + (body[j] - '0');
      ++j;
    }
    if (j == i + 1 || j + 3 >= body.size() || body[j] != '[' ||
        !std::isdigit(static_cast<unsigned char>(body[j + 1])) ||
        !std::isdigit(static_cast<unsigned char>(body[j + 2])) || body[j + 3] != ']')
    {
      throw ProtocolError("DPRNT: malformed variable reference at \"" + std::string(body.substr(i, 12)) +
                          "\" (expected #nnnn[wf])");
    }
    out += formatValue(lookup(variable), body[j + 1] - '0', body[j + 2] - '0');
    i = j + 4;
  }
  return out;
}
}  // namespace dprnt
}  // namespace cnc_bridge
