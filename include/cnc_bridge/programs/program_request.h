// Program requests from the control: the operator asks for a program without walking to a PC, as
// DNC systems allow. The request is a short program the control punches or drops in a share's
// requests/ folder, whose comment reads (LOAD O1234) or (SEND O1234) (send me program 1234) or
// (SAVE O1234) (take the program that follows), or a DPRNT line `LOAD O1234` (or a shop's own
// words: RequestWords). The words, the O and the spaces are matched loosely because operators
// type them at the control: `(load 1234)`, `( LOAD O01234 )` and `LOAD O1234` on a DPRNT line all
// count.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "cnc_bridge/programs/program_name.h"

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
  std::string word;  ///< the word as recognised (LOAD, SEND, SAVE, or one of RequestWords)
};

/// \brief The words that make a comment a request (a shop may use its own: `(GET O1234)`).
struct RequestWords
{
  std::vector<std::string> load = {"LOAD", "SEND"};  ///< send me the program
  std::vector<std::string> save = {"SAVE"};          ///< take the program that follows

  /// \brief Words from parameter text, separated by spaces or commas ("LOAD SEND GET").
  /// \throws ConfigError for an empty list, a word that is not 2 to 12 letters, or a word in both
  ///         lists, naming \p load_name or \p save_name.
  static RequestWords parse(const std::string& load, const std::string& save, const std::string& load_name,
                            const std::string& save_name);
  /// \brief "(LOAD O1234), (SEND O1234) or (SAVE O1234)", for messages.
  std::string describe() const;
};

/// \brief Finds a request in \p text: the first `(WORD O1234)` comment in it, or, when
/// \p bare_line is set, a line that is just `WORD O1234` (a DPRNT line). Only the first
/// kRequestHeadBytes are looked at. Never throws.
/// How much of a request (a request file, a punch) is looked at: read no more than this of a file.
constexpr size_t kRequestHeadBytes = 4096;

std::optional<ProgramRequest> recogniseRequest(const std::string& text, bool bare_line = false,
                                               const RequestWords& words = RequestWords());

/// \brief What to do about a request, the same on every wire (a punch on RS-232, a request file
/// in a share, a DPRNT line), so that a control is answered alike whichever way it asked.
struct RequestDecision
{
  enum class Action
  {
    kSend,     ///< send `program` to the control
    kReceive,  ///< take the program the control sends next and keep it as `program`
    kRefuse    ///< do neither: `outcome` and `shown` say why
  };
  Action action = Action::kRefuse;
  std::string program;  ///< the program's file name (by the name pattern)
  std::string outcome;  ///< refused: why, in words for the log and program_requests
  std::string shown;    ///< refused: why, short and uppercase, for the control's screen
};

/// \brief Maps a request onto an action: LOAD/SEND of a program that is in \p program_root and not
/// protected -> kSend; SAVE -> kReceive (receiving a protected number is allowed: it overwrites
/// nothing on the control); anything else -> kRefuse with the reason. Does not throw.
/// \param program_root the directory programs are sent from (the existence of the file is checked).
RequestDecision decideRequest(const ProgramRequest& request, const NamePattern& pattern, const ProtectedRange& range,
                              const std::string& program_root);

/// \brief What a punch or request file that holds no request is answered with:
/// "no (LOAD O1234), (SEND O1234) or (SAVE O1234) in it".
std::string noRequestOutcome(const RequestWords& words = RequestWords());

/// \brief The longest reason an answer program's comment carries: what a control shows of a
/// program's comment in its program list without cutting it (a Haas shows about 30 characters).
constexpr size_t kAnswerCommentLength = 32;

/// \brief A short program that tells the operator at the control why a request was not served:
/// `%`, `O<number> (<SHOWN>)`, `M30`, `%`. \p shown is cut to kAnswerCommentLength and
/// limited to what a control shows and takes in a comment (uppercase letters, digits, space and
/// . , : - /; anything else becomes a space, so no parenthesis can end the comment early).
/// \param number the answer's own O number: the number of the request program the operator
/// punched, so the answer replaces it on the control and overwrites nothing else.
std::string answerProgram(uint32_t number, const std::string& shown);
}  // namespace cnc_bridge::programs
