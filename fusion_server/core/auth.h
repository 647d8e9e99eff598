#pragma once
// Bearer tokens and roles (MISSION part G, issue 8). Pure: no gRPC, no SQLite.
//
// Roles:
//   sensor — may only open SensorService.Stream, and only as the camera its token is bound to
//            (a bootstrap fleet token from --sensor-token may stream as any registered camera);
//   viewer — may only read scene state (Subscribe, GetStaticModel);
//   admin  — may manage cameras and tokens, and may also read scene state.
// Tokens are kept as SHA-256 digests only, in memory and in the store; a presented token is
// hashed and looked up, comparing the secret part of the digest in constant time (issue 14, see
// TokenRegistry). Unknown or revoked token: Unauthenticated. Known token outside its role's
// rights: PermissionDenied naming the role and the call.
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace ave {

enum class Role { kSensor, kViewer, kAdmin };

const char* RoleName(Role role);
absl::StatusOr<Role> ParseRole(const std::string& name);

// What a call may do. Stream names the camera it streams as.
// kManageModels: store avatar sequences (issue 17) and other models, admin only.
enum class Action { kStream, kSubscribe, kReadModel, kManageCameras, kManageTokens, kManageModels };
const char* ActionName(Action action);

struct Principal {
  Role role = Role::kViewer;
  std::string camera_id;  // sensor tokens bound to one camera; empty = any (bootstrap fleet token)
  std::string token_id;   // first 12 hex characters of the hash: names the token in logs and audit
  bool bootstrap = false;  // from the command line / environment rather than the store
};

// SHA-256 of `token` as 64 lowercase hex characters (OpenSSL libcrypto).
std::string HashToken(std::string_view token);

// Whether `a` and `b` are equal, in time that depends on their lengths only, not on where they
// differ (OpenSSL CRYPTO_memcmp). Lengths are not secret here: every digest is 64 characters.
bool ConstantTimeEquals(std::string_view a, std::string_view b);

// A fresh random token: 32 bytes from the OpenSSL CSPRNG as 64 hex characters.
absl::StatusOr<std::string> NewRandomToken();

// Tokens by digest. Lookup goes by the token id, the digest's first 12 hex characters, which is
// public (logs, audit rows, ListTokens print it) and so may be compared with an ordinary,
// short-circuiting map search; the whole digest of each candidate with that id is then compared
// with ConstantTimeEquals. The time a lookup takes thus reveals nothing beyond whether some
// token's public id matches the presented token's digest prefix, and that only tells an attacker
// about SHA-256 outputs, not about any token.
class TokenRegistry {
 public:
  // Adds a token by its hash; replaces an earlier entry with the same hash.
  void Add(const std::string& hash, Principal principal);
  // Forgets every token whose hash starts with `hash_prefix`; returns how many.
  int Revoke(const std::string& hash_prefix);
  size_t size() const;

  // Unauthenticated for an empty, oversize, unknown or revoked token.
  absl::StatusOr<Principal> Authenticate(std::string_view token) const;

 private:
  struct Entry {
    std::string hash;  // 64 hex characters
    Principal principal;
  };
  mutable std::mutex mu_;
  std::multimap<std::string, Entry> by_id_;  // key: token id (hash prefix, public)
};

// Ok, or PermissionDenied naming the role, the action and (for sensors) both cameras.
absl::Status Authorize(const Principal& who, Action action, const std::string& camera_id = {});

}  // namespace ave
