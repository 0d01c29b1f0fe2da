// Request recognition and the answer program (see program_request.h).
#include "cnc_bridge/programs/program_request.h"

#include <cctype>
#include <filesystem>

#include "cnc_bridge/common/error.h"

#include "cnc_bridge/programs/program_name.h"

namespace cnc_bridge::programs
{
namespace
{
constexpr size_t kLookAt = 4096;

std::string upper(const std::string& text)
{
  std::string out = text;
  for (char& c : out)
    c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return out;
}

/// "LOAD O1234" (after trimming, uppercase) -> the request; anything else -> nothing.
std::optional<ProgramRequest> parseWords(const std::string& words)
{
  size_t i = 0;
  auto skip_spaces = [&]
  {
    while (i < words.size() && (words[i] == ' ' || words[i] == '\t'))
      ++i;
  };
  skip_spaces();
  ProgramRequest request;
  for (const char* word : {"LOAD", "SEND", "SAVE"})
  {
    if (words.compare(i, 4, word) == 0)
      request.word = word;
  }
  if (request.word.empty())
    return std::nullopt;
  request.kind = request.word == "SAVE" ? ProgramRequest::Kind::kSave : ProgramRequest::Kind::kLoad;
  i += 4;
  const size_t before = i;
  skip_spaces();
  if (i == before)
    return std::nullopt;  // "LOADO1234" is not a request
  if (i < words.size() && words[i] == 'O')
    ++i;
  uint32_t number = 0;
  size_t digits = 0;
  while (i < words.size() && std::isdigit(static_cast<unsigned char>(words[i])) && digits < 8)
  {
    number = number * 10 + static_cast<uint32_t>(words[i++] - '0');
    ++digits;
  }
  skip_spaces();
  if (digits == 0 || i != words.size())
    return std::nullopt;
  request.number = number;
  return request;
}
}  // namespace

std::optional<ProgramRequest> recogniseRequest(const std::string& all, bool bare_line)
{
  const std::string text = upper(all.substr(0, kLookAt));
  for (size_t open = text.find('('); open != std::string::npos; open = text.find('(', open + 1))
  {
    const size_t close = text.find_first_of(")\r\n", open + 1);
    if (close == std::string::npos || text[close] != ')')
      continue;
    if (auto request = parseWords(text.substr(open + 1, close - open - 1)))
      return request;
  }
  if (bare_line)
  {
    size_t start = 0;
    while (start < text.size())
    {
      size_t end = text.find_first_of("\r\n", start);
      if (end == std::string::npos)
        end = text.size();
      if (auto request = parseWords(text.substr(start, end - start)))
        return request;
      start = end + 1;
    }
  }
  return std::nullopt;
}

const char* const kNoRequestOutcome = "no (LOAD O1234), (SEND O1234) or (SAVE O1234) in it";

RequestDecision decideRequest(const ProgramRequest& request, const NamePattern& pattern, const ProtectedRange& range,
                              const std::string& program_root)
{
  RequestDecision decision;
  decision.program = pattern.format(request.number);
  const std::string label = programLabel(request.number);
  if (request.kind == ProgramRequest::Kind::kSave)
  {
    decision.action = RequestDecision::Action::kReceive;
    return decision;
  }
  if (range.contains(request.number))
  {
    try
    {
      range.check(decision.program, request.number, std::nullopt);
    }
    catch (const Error& e)
    {
      decision.outcome = e.what();
      decision.shown = label + " PROTECTED - NOT SENT";
      return decision;
    }
  }
  std::error_code error;
  if (!std::filesystem::is_regular_file(program_root + "/" + decision.program, error))
  {
    decision.outcome = "no " + decision.program + " in " + program_root;
    decision.shown = label + " NOT FOUND IN PROGRAMS";
    return decision;
  }
  decision.action = RequestDecision::Action::kSend;
  return decision;
}

std::string answerProgram(uint32_t number, const std::string& shown)
{
  std::string comment;
  for (const char c : upper(shown.substr(0, kAnswerCommentLength)))
  {
    const bool allowed =
        std::isalnum(static_cast<unsigned char>(c)) || std::string(" .,:-/").find(c) != std::string::npos;
    comment.push_back(allowed ? c : ' ');
  }
  while (!comment.empty() && comment.back() == ' ')
    comment.pop_back();
  return "%\n" + programLabel(number) + " (" + comment + ")\nM30\n%\n";
}
}  // namespace cnc_bridge::programs
