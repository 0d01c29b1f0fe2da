// libFuzzer target: the program-request recogniser on arbitrary text (punched programs, DPRNT
// lines). Must not crash; a recognised request's answer program must carry the request's number
// and a comment no longer than kAnswerCommentLength.
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
  for (const bool bare : {false, true})
  {
    if (const auto request = recogniseRequest(text, bare))
    {
      // The answer carries its own number and a comment no longer than a control shows, whatever
      // the reason's text (the recognised text stands in for any reason here).
      const ProgramHeader header = readHeader(answerProgram(request->number, text));
      if (header.number != request->number || header.comment.size() > kAnswerCommentLength)
        std::abort();
    }
  }
  return 0;
}
