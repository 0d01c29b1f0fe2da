// Program requests as an operator types them at a control, and the answer program.
#include <gtest/gtest.h>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/programs/program_name.h"
#include "cnc_bridge/programs/program_request.h"

using namespace cnc_bridge::programs;

TEST(ProgramRequest, RecognisedInAPunchedProgramOrADprntLine)
{
  auto r = recogniseRequest("%\nO00001 (LOAD O1234)\nM30\n%\n");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->kind, ProgramRequest::Kind::kLoad);
  EXPECT_EQ(r->number, 1234u);
  r = recogniseRequest("%\n:0002\n( send o01234 )\n%");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->word, "SEND");
  EXPECT_EQ(r->number, 1234u);
  r = recogniseRequest("%\nO0003 (SAVE 5555)\n%\n");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->kind, ProgramRequest::Kind::kSave);
  EXPECT_EQ(r->number, 5555u);
  // The first comment that is a request counts; other comments are passed over.
  r = recogniseRequest("%\nO0004 (OPERATOR SHIFT 2)\n(LOAD O77)\n%\n");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->number, 77u);
  EXPECT_FALSE(recogniseRequest("LOAD O1234"));  // a bare line only on a DPRNT stream
  r = recogniseRequest("LOAD O1234\r\n", true);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->number, 1234u);
  for (const char* not_one :
       {"(LOADO1234)", "(LOAD)", "(LOAD O12X)", "(RELOAD O1)", "(LOAD O1234", "(UNLOAD 5)", "(LOAD O123456789)", ""})
    EXPECT_FALSE(recogniseRequest(not_one, true)) << not_one;
}

TEST(ProgramRequest, AShopsOwnWordsReplaceTheDefaults)
{
  const RequestWords words = RequestWords::parse("get, load", "put", "~request_load_words", "~request_save_words");
  auto r = recogniseRequest("%\nO00001 (GET O1234)\nM30\n%\n", false, words);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->word, "GET");
  EXPECT_EQ(r->kind, ProgramRequest::Kind::kLoad);
  r = recogniseRequest("PUT 77", true, words);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->kind, ProgramRequest::Kind::kSave);
  EXPECT_EQ(r->number, 77u);
  EXPECT_FALSE(recogniseRequest("(SEND O1234)", false, words));  // not one of this shop's words
  EXPECT_FALSE(recogniseRequest("(GETO1234)", false, words));
  EXPECT_EQ(noRequestOutcome(words), "no (GET O1234), (LOAD O1234) or (PUT O1234) in it");
  EXPECT_EQ(noRequestOutcome(), "no (LOAD O1234), (SEND O1234) or (SAVE O1234) in it");
  // Of two words that both fit, the longer counts: SENDALL is not SEND followed by garbage.
  const RequestWords nested = RequestWords::parse("SEND SENDALL", "SAVE", "load", "save");
  r = recogniseRequest("(SENDALL O5)", false, nested);
  ASSERT_TRUE(r);
  EXPECT_EQ(r->word, "SENDALL");
  for (const auto& bad : std::vector<std::pair<std::string, std::string>>{
           {"", "SAVE"}, {"LOAD", " , "}, {"LO4D", "SAVE"}, {"L", "SAVE"}, {"LOAD SAVE", "SAVE"}})
    EXPECT_THROW(RequestWords::parse(bad.first, bad.second, "~request_load_words", "~request_save_words"),
                 cnc_bridge::ConfigError)
        << bad.first << " / " << bad.second;
}
