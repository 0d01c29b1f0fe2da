// Haas DPRNT output formatting: how a control turns `DPRNT[X#1[44]*Z#1[03]]` into the text that
// leaves the serial port. The simulator prints with it, and the tests check it against the
// examples of the Haas mill programming manual, so the parser is tested against what a control
// really prints rather than against itself.
#pragma once

#include <functional>
#include <string>
#include <string_view>

namespace cnc_bridge
{
namespace dprnt
{
/// \brief Formats one macro variable value as `#var[wf]` prints it.
///
/// Rules (Haas mill programming manual, "Formatted Output"; docs/protocols/dprnt.md#haas-number-format):
///   - w places are reserved for the whole part and f for the fraction; 1 <= w + f <= 8;
///   - the fraction is rounded to f places (half away from zero, on the decimal value), and printed
///     with trailing zeros; no decimal point when f = 0, and then the whole part is printed as is
///     (the manual prints 1.5436 with [40] as "1": the fraction is dropped, not rounded);
///   - at least one whole digit is printed, even for w = 0 ("0.5" for [01]);
///   - a whole part shorter than w gets leading spaces; a longer one widens the field.
/// The manual does not say where a minus sign goes; we print it right before the first digit and
/// count it inside the w places (like printf's field width), so "[44]" of -0.0125 is "  -0.0125".
/// \throws ConfigError if w or f is out of range.
std::string formatValue(double value, int whole, int fraction);

/// \brief Formats the contents of a DPRNT statement (the text between the outer brackets).
///
/// Text characters are copied, `*` prints as a space (the manual's replacement for spaces, which
/// a control strips from blocks), `#nnnn[wf]` prints a variable through formatValue().
/// \param lookup returns the value of macro variable n.
/// \returns the line without its end (the control sends CR after every DPRNT block).
/// \throws ProtocolError for a malformed `#` reference or format.
std::string formatStatement(std::string_view body, const std::function<double(int)>& lookup);
}  // namespace dprnt
}  // namespace cnc_bridge
