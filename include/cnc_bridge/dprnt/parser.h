// The tolerant reader of DPRNT lines: whatever a macro programmer chose to print, pull out the
// numbers and the words in front of them. `X1.5436 Z 1.544 T 1`, `Z OFFSET IS -1.2345`,
// `#5223 -0.0125` and a bare `-0.0125` all become label/value pairs, so that rules and users can
// pick values by name without writing a regular expression for every program.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace cnc_bridge
{
namespace dprnt
{
/// \brief One number of a line and the label printed in front of it.
struct LabeledValue
{
  std::string label;  ///< words before the number, single-spaced, trailing "=", ":", "IS" removed; may be empty
  double value = 0.0;
};

/// \brief Parses one DPRNT line into label/value pairs. Thread-safe (no state).
///
/// Grammar, as read from what controls print (Haas manual examples; docs/protocols/dprnt.md#lines-to-values):
///   - a number is [+-] digits [. digits] or [+-] . digits; "1." is 1. A sign separated from the
///     digits by spaces still belongs to them ("X - 1.5" is -1.5) because Haas pads after the label;
///   - a number glued to a word ("X1.5", "T1") is that word's value; "#5223" is a label
///     (a variable name), not a number;
///   - a label is the text since the previous number, with runs of spaces collapsed and a trailing
///     "=", ":" or the word "IS" dropped ("Z OFFSET IS -1.2345" -> "Z OFFSET"); when its last word
///     is a single letter (an NC address) or a #variable, that word alone ("PROBE X 1.5" -> "X");
///   - text after the last number is ignored (it has no value); a line without numbers yields
///     nothing.
/// Spacing between fields is not significant: the manual's own example is printed with
/// uncertain spacing, and real output pads short whole parts with spaces.
class LineParser
{
 public:
  /// \brief Parses \p line, replacing the contents of \p out (reusing its storage).
  /// \returns the number of values found.
  static size_t parse(std::string_view line, std::vector<LabeledValue>& out);

  /// \returns the pairs of \p line (convenience for tests and callers that do not reuse storage).
  static std::vector<LabeledValue> parse(std::string_view line)
  {
    std::vector<LabeledValue> out;
    parse(line, out);
    return out;
  }
};

/// \returns the value of the first pair labelled \p label (exact match), or nullptr.
const LabeledValue* findLabel(const std::vector<LabeledValue>& values, std::string_view label);
}  // namespace dprnt
}  // namespace cnc_bridge
