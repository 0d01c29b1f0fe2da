// Request recognition and the answer program (see program_request.h).
#include "cnc_bridge/programs/program_request.h"

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "cnc_bridge/common/error.h"

#include "cnc_bridge/programs/program_name.h"

namespace cnc_bridge::programs
{
namespace
{
std::string upper(const std::string& text)
{
  std::string out = text;
  for (char& c : out)
    c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return out;
}

/// "LOAD O1234" (after trimming, uppercase) -> the request; anything else -> nothing.
std::optional<ProgramRequest> parseWords(const std::string& words, const RequestWords& known)
{
  size_t i = 0;
  auto skip_spaces = [&]
  {
    while (i < words.size() && (words[i] == ' ' || words[i] == '\t'))
      ++i;
  };
  skip_spaces();
  ProgramRequest request;
  bool save = false;
  for (const auto* list : {&known.load, &known.save})
  {
    for (const std::string& word : *list)
    {
      // The word must be followed by a space ("LOADO1234" is not a request); of two words that
      // both fit, the longer one counts.
      const size_t end = i + word.size();
      if (words.compare(i, word.size(), word) == 0 && end < words.size() && (words[end] == ' ' || words[end] == '\t') &&
          word.size() > request.word.size())
      {
        request.word = word;
        save = list == &known.save;
      }
    }
  }
  if (request.word.empty())
    return std::nullopt;
  request.kind = save ? ProgramRequest::Kind::kSave : ProgramRequest::Kind::kLoad;
  i += request.word.size();
  skip_spaces();
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

RequestWords RequestWords::parse(const std::string& load, const std::string& save, const std::string& load_name,
                                 const std::string& save_name)
{
  auto split = [](const std::string& text, const std::string& name)
  {
    std::vector<std::string> words;
    std::string word;
    for (const char c : upper(text) + " ")
    {
      if (c != ' ' && c != ',' && c != '\t')
      {
        word.push_back(c);
        continue;
      }
      if (word.empty())
        continue;
      const bool letters = std::all_of(word.begin(), word.end(), [](char l) { return l >= 'A' && l <= 'Z'; });
      if (!letters || word.size() < 2 || word.size() > 12)
        throw ConfigError(name + ": '" + word + "' is not a request word (2 to 12 letters)");
      words.push_back(word);
      word.clear();
    }
    if (words.empty())
      throw ConfigError(name + " holds no word (e.g. 'LOAD SEND')");
    return words;
  };
  RequestWords words;
  words.load = split(load, load_name);
  words.save = split(save, save_name);
  for (const std::string& word : words.load)
  {
    if (std::find(words.save.begin(), words.save.end(), word) != words.save.end())
      throw ConfigError("'" + word + "' is in both " + load_name + " and " + save_name);
  }
  return words;
}

std::string RequestWords::describe() const
{
  std::vector<std::string> all = load;
  all.insert(all.end(), save.begin(), save.end());
  std::string out;
  for (size_t n = 0; n < all.size(); ++n)
    out += (n == 0 ? "" : n + 1 == all.size() ? " or " : ", ") + ("(" + all[n] + " O1234)");
  return out;
}

std::optional<ProgramRequest> recogniseRequest(const std::string& all, bool bare_line, const RequestWords& words)
{
  const std::string text = upper(all.substr(0, kRequestHeadBytes));
  for (size_t open = text.find('('); open != std::string::npos; open = text.find('(', open + 1))
  {
    const size_t close = text.find_first_of(")\r\n", open + 1);
    if (close == std::string::npos || text[close] != ')')
      continue;
    if (auto request = parseWords(text.substr(open + 1, close - open - 1), words))
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
      if (auto request = parseWords(text.substr(start, end - start), words))
        return request;
      start = end + 1;
    }
  }
  return std::nullopt;
}

std::string noRequestOutcome(const RequestWords& words)
{
  return "no " + words.describe() + " in it";
}

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
