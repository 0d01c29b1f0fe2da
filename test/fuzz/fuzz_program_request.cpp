// libFuzzer target: the program-request recogniser on arbitrary text (punched programs, DPRNT
// lines), with the default words and a shop's own. Must not crash; a recognised request's word must
// be one it was given, of its kind; its answer program must carry the request's number and a
// comment no longer than kAnswerCommentLength.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/programs/program_request.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size)
{
  using namespace cnc_bridge::programs;
  const std::string text(reinterpret_cast<const char*>(data), size);
  // The default words and a shop's own, one a prefix of another (the longer must win).
  static const RequestWords kOwn = RequestWords::parse("GET GETALL LOAD", "PUT", "load", "save");
  for (const RequestWords* words : {static_cast<const RequestWords*>(nullptr), &kOwn})
  {
    for (const bool bare : {false, true})
    {
      const auto request = words ? recogniseRequest(text, bare, *words) : recogniseRequest(text, bare);
      if (!request)
        continue;
      const RequestWords& known = words ? *words : RequestWords();
      const bool save = request->kind == ProgramRequest::Kind::kSave;
      const auto& list = save ? known.save : known.load;
      if (std::find(list.begin(), list.end(), request->word) == list.end())
        std::abort();  // a word the node was not given, or of the wrong kind
      // The answer carries its own number and a comment no longer than a control shows, whatever
      // the reason's text (the recognised text stands in for any reason here).
      const ProgramHeader header = readHeader(answerProgram(request->number, text));
      if (header.number != request->number || header.comment.size() > kAnswerCommentLength)
        std::abort();
    }
  }
  return 0;
}
