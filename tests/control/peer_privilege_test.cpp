// The privileged-group check of the control socket against this machine's real user and group
// database (Debian's base-passwd guarantees root/0 and daemon/1, with no members in group 0).
#include "control/peer_privilege.hpp"

#include <grp.h>
#include <pwd.h>
#include <sys/types.h>

#include <catch2/catch.hpp>
#include <string>
#include <utility>
#include <vector>

using ds1928::control::peer_is_privileged;
using ds1928::control::PeerCredentials;

namespace {

std::string group_name(gid_t gid) {
  const group* g = getgrgid(gid);
  REQUIRE(g != nullptr);
  return g->gr_name;
}

// uid 1 (Debian's "daemon"): an ordinary user with a primary group and nothing else.
const passwd& ordinary_user() {
  const passwd* pw = getpwuid(1);
  REQUIRE(pw != nullptr);
  return *pw;
}

constexpr gid_t kNoGid = static_cast<gid_t>(-1);

}  // namespace

TEST_CASE("root is privileged whatever the group", "[control][privilege]") {
  CHECK(peer_is_privileged(PeerCredentials{1, 0, 0}, "ds1928-no-such-group"));
  CHECK(peer_is_privileged(PeerCredentials{1, 0, kNoGid}, ""));
}

TEST_CASE("an unknown peer, an empty or unknown group is not privileged", "[control][privilege]") {
  const passwd& user = ordinary_user();
  const std::string primary = group_name(user.pw_gid);
  CHECK_FALSE(peer_is_privileged(PeerCredentials{1, user.pw_uid, user.pw_gid}, ""));
  CHECK_FALSE(
      peer_is_privileged(PeerCredentials{1, user.pw_uid, user.pw_gid}, "ds1928-no-such-group"));
  // Credentials the kernel could not give (uid -1) never pass, even with the group's gid.
  CHECK_FALSE(peer_is_privileged(PeerCredentials{1, static_cast<uid_t>(-1), user.pw_gid}, primary));
}

TEST_CASE("the peer's own gid, its user's primary group or a supplementary one is privileged",
          "[control][privilege]") {
  const passwd& user = ordinary_user();
  const std::string primary = group_name(user.pw_gid);
  // The socket credentials carry the group itself.
  CHECK(peer_is_privileged(PeerCredentials{1, user.pw_uid, user.pw_gid}, primary));
  // The credentials carry another gid (setgid program), but the user's primary group is it:
  // found through getgrouplist.
  CHECK(peer_is_privileged(PeerCredentials{1, user.pw_uid, kNoGid}, primary));
  // A uid without a passwd entry has no group list.
  CHECK_FALSE(peer_is_privileged(PeerCredentials{1, 0x7FFF'FF00, kNoGid}, primary));
  // Group 0 has no members on Debian: the ordinary user is not in it.
  CHECK_FALSE(peer_is_privileged(PeerCredentials{1, user.pw_uid, user.pw_gid}, group_name(0)));

  // Supplementary membership, where this machine has one ("ssl-cert:x:103:postgres"): every
  // member of a group that is not its primary group is privileged for it.
  // The database is walked first: the lookups under test must not run inside getgrent's walk.
  std::vector<std::pair<std::string, std::string>> memberships;  // (user, group)
  setgrent();
  while (const group* g = getgrent())
    for (char** m = g->gr_mem; m != nullptr && *m != nullptr; ++m)
      memberships.emplace_back(*m, g->gr_name);
  endgrent();
  int checked = 0;
  for (const auto& [user_name, name] : memberships) {
    const passwd* pw = getpwnam(user_name.c_str());
    if (pw == nullptr || pw->pw_uid == 0) continue;
    const PeerCredentials peer{1, pw->pw_uid, pw->pw_gid};
    INFO(user_name << " in " << name);
    CHECK(peer_is_privileged(peer, name));
    ++checked;
  }
  INFO("supplementary memberships checked: " << checked);
  SUCCEED();
}
