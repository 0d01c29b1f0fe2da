// share_node's settings checked without ROS (share_settings.h): exactly one of ~url and
// ~serve_dir, a served folder that must exist and be local, the requests folder a plain name in
// the share, the archive beside the program folder unless given, at least one version kept; a
// password in an address refused without repeating it.
#include <gtest/gtest.h>

#include <string>
#include <tuple>

#include "cnc_bridge/common/error.h"
#include "cnc_bridge/share/share_settings.h"
#include "temp_dir.h"

using namespace cnc_bridge;
using namespace cnc_bridge::share;
using cnc_bridge::test::TempDir;

namespace
{
/// shareAddress() with the parameters' names as share_node gives them; the ConfigError's text,
/// or "" when it returned (the address in \p address).
std::string addressError(const std::string& url, const std::string& serve_dir, std::string* address = nullptr)
{
  try
  {
    const std::string given = shareAddress(url, serve_dir, "/vf2/share/url", "/vf2/share/serve_dir");
    if (address != nullptr)
      *address = given;
    return "";
  }
  catch (const ConfigError& e)
  {
    return e.what();
  }
}
}  // namespace

TEST(ShareAddress, ExactlyOneOfUrlAndServeDir)
{
  TempDir dir{"cnc_share_settings"};
  EXPECT_EQ(addressError("", ""),
            "give exactly one of /vf2/share/url (a machine's share) and /vf2/share/serve_dir (a folder the PC serves "
            "to the controls), not neither");
  EXPECT_EQ(addressError("smb://vf2/memory", dir.path),
            "give exactly one of /vf2/share/url (a machine's share) and /vf2/share/serve_dir (a folder the PC serves "
            "to the controls), not both");
}

TEST(ShareAddress, AUrlIsTakenAsGiven)
{
  std::string address;
  EXPECT_EQ(addressError("smb://cnc@vf2:1445/memory/programs", "", &address), "");
  EXPECT_EQ(address, "smb://cnc@vf2:1445/memory/programs");
  // A local ~url need not exist yet: the store says so at its first call.
  EXPECT_EQ(addressError("/no/such/folder", "", &address), "");
  EXPECT_EQ(address, "/no/such/folder");
}

TEST(ShareAddress, APasswordInTheAddressIsRefusedAndNotRepeated)
{
  const std::string password = "Pw-31c4e";
  for (const auto& [url, serve_dir, named] :
       {std::tuple<std::string, std::string, std::string>{"smb://cnc:" + password + "@vf2/memory", "", "url"},
        {"smb://WORKGROUP;cnc:" + password + "@vf2:445/memory/programs", "", "url"},
        {"", "smb://cnc:" + password + "@vf2/memory", "serve_dir"}})
  {
    const std::string error = addressError(url, serve_dir);
    EXPECT_EQ(
        error.rfind("/vf2/share/" + named + " holds user information with a password (user:password@): refused", 0), 0u)
        << error;
    EXPECT_NE(error.find("credentials file in smbclient's format"), std::string::npos) << error;
    EXPECT_EQ(error.find(password), std::string::npos) << error;
  }
  EXPECT_EQ(shownAddress("smb://cnc:" + password + "@vf2/memory"), "smb://***@vf2/memory");
  EXPECT_EQ(shownAddress("smb://cnc@vf2/memory"), "smb://cnc@vf2/memory");
  EXPECT_EQ(shownAddress("/srv/a:b@c"), "/srv/a:b@c");      // a local folder has no user information
  EXPECT_EQ(addressError("smb://cnc@vf2/memory", ""), "");  // a user without a password is fine
}

TEST(ShareAddress, AServedFolderIsAnExistingLocalFolder)
{
  TempDir dir{"cnc_share_settings"};
  std::string address;
  EXPECT_EQ(addressError("", dir.path, &address), "");
  EXPECT_EQ(address, dir.path);
  EXPECT_EQ(addressError("", "smb://vf2/memory"),
            "/vf2/share/serve_dir is a local folder the PC's Samba serves, not smb://vf2/memory: give a machine's "
            "share as ~url");
  EXPECT_EQ(addressError("", dir.file("missing")),
            "/vf2/share/serve_dir " + dir.file("missing") +
                " is not a folder: create it and serve it with Samba (config/share/served_share.smb.conf)");
  const std::string file = dir.write("O01234.nc", "%\nO01234\nM30\n%\n");
  EXPECT_EQ(addressError("", file), "/vf2/share/serve_dir " + file +
                                        " is not a folder: create it and serve it with Samba "
                                        "(config/share/served_share.smb.conf)");
}

TEST(RequestsAddress, AFolderInsideTheShare)
{
  EXPECT_EQ(requestsAddress("smb://vf2/memory", "requests"), "smb://vf2/memory/requests");
  EXPECT_EQ(requestsAddress("/srv/cnc_programs", "cell/requests"), "/srv/cnc_programs/cell/requests");
  EXPECT_THROW(requestsAddress("smb://vf2/memory", "../requests"), ConfigError);
  EXPECT_THROW(requestsAddress("smb://vf2/memory", "/requests"), ConfigError);
  EXPECT_THROW(requestsAddress("smb://vf2/memory", "a//b"), ConfigError);
}

TEST(ArchiveSettings, BesideTheProgramFolderUnlessGiven)
{
  EXPECT_EQ(archiveDir(std::nullopt, "/home/cnc/nc_programs"), "/home/cnc/nc_programs.archive");
  EXPECT_EQ(archiveDir(std::string("/srv/archive"), "/home/cnc/nc_programs"), "/srv/archive");
}

TEST(ArchiveSettings, AtLeastOneVersionIsKept)
{
  EXPECT_EQ(archiveKeep(20), 20u);
  EXPECT_EQ(archiveKeep(1), 1u);
  EXPECT_EQ(archiveKeep(0), 1u);
  EXPECT_EQ(archiveKeep(-3), 1u);
}
