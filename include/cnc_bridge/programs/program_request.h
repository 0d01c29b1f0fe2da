// Program requests from the control: the operator asks for a program without walking to a PC, as
// DNC systems allow. The request is a short program the control punches or drops in a share's
// requests/ folder, whose comment reads (LOAD O1234) or (SEND O1234) (send me program 1234) or
// (SAVE O1234) (take the program that follows), or a DPRNT line `LOAD O1234`. The words, the O
// and the spaces are matched loosely because operators type them at the control: `(load 1234)`,
// `( LOAD O01234 )` and `LOAD O1234` on a DPRNT line all count.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

namespace cnc_bridge::programs
{
/// \brief What the control asked for.
struct ProgramRequest
{
  enum class Kind
  {
    kLoad,  ///< LOAD or SEND: send program `number` to the control
    kSave   ///< SAVE: receive the program the control sends next and keep it as `number`
  };
  Kind kind = Kind::kLoad;
  uint32_t number = 0;
  std::string word;  ///< LOAD, SEND or SAVE as recognised
};

/// \brief Finds a request in \p text: the first `(WORD O1234)` comment in it, or, when
/// \p bare_line is set, a line that is just `WORD O1234` (a DPRNT line). Only the first 4 KB are
/// looked at. Never throws.
std::optional<ProgramRequest> recogniseRequest(const std::string& text, bool bare_line = false);

/// \brief A short program that tells the operator at the control why a request was not served:
/// `%`, `O<number> (CANNOT LOAD O01234: <REASON>)`, `M30`, `%`, the reason in the characters a
/// control shows in a comment (uppercase letters, digits, space and . , : - /).
std::string answerProgram(uint32_t number, const std::string& word, const std::string& reason);
}  // namespace cnc_bridge::programs
