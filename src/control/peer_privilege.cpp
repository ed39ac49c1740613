#include "control/peer_privilege.hpp"

#include <grp.h>
#include <pwd.h>
#include <unistd.h>

#include <algorithm>
#include <vector>

namespace ds1928::control {

bool peer_is_privileged(const PeerCredentials& peer, const std::string& group_name) {
  if (peer.uid == 0) return true;
  if (group_name.empty() || peer.uid == static_cast<uid_t>(-1)) return false;
  std::vector<char> buffer(16384);
  group grp{};
  group* found_group = nullptr;
  if (getgrnam_r(group_name.c_str(), &grp, buffer.data(), buffer.size(), &found_group) != 0 ||
      found_group == nullptr)
    return false;
  const gid_t wanted = grp.gr_gid;
  if (peer.gid == wanted) return true;
  std::vector<char> pbuffer(16384);
  passwd pw{};
  passwd* found_user = nullptr;
  if (getpwuid_r(peer.uid, &pw, pbuffer.data(), pbuffer.size(), &found_user) != 0 ||
      found_user == nullptr)
    return false;
  int count = 64;
  std::vector<gid_t> groups(static_cast<std::size_t>(count));
  if (getgrouplist(pw.pw_name, pw.pw_gid, groups.data(), &count) < 0) {
    groups.resize(static_cast<std::size_t>(count));
    if (getgrouplist(pw.pw_name, pw.pw_gid, groups.data(), &count) < 0) return false;
  }
  groups.resize(static_cast<std::size_t>(count));
  return std::find(groups.begin(), groups.end(), wanted) != groups.end();
}

}  // namespace ds1928::control
