#include "fusion_server/core/auth.h"

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/rand.h>

#include "absl/strings/str_cat.h"

namespace ave {
namespace {

constexpr size_t kMaxTokenBytes = 4096;
constexpr size_t kTokenIdChars = 12;

std::string Hex(const unsigned char* bytes, size_t n) {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string out(2 * n, '0');
  for (size_t i = 0; i < n; ++i) {
    out[2 * i] = kDigits[bytes[i] >> 4];
    out[2 * i + 1] = kDigits[bytes[i] & 15];
  }
  return out;
}

}  // namespace

const char* RoleName(Role role) {
  switch (role) {
    case Role::kSensor: return "sensor";
    case Role::kViewer: return "viewer";
    case Role::kAdmin: return "admin";
  }
  return "unknown";
}

absl::StatusOr<Role> ParseRole(const std::string& name) {
  if (name == "sensor") return Role::kSensor;
  if (name == "viewer") return Role::kViewer;
  if (name == "admin") return Role::kAdmin;
  return absl::InvalidArgumentError(absl::StrCat("role must be sensor, viewer or admin, not '", name, "'"));
}

const char* ActionName(Action action) {
  switch (action) {
    case Action::kStream: return "stream frames";
    case Action::kSubscribe: return "subscribe to scene state";
    case Action::kReadModel: return "read the static model";
    case Action::kManageCameras: return "manage cameras";
    case Action::kManageTokens: return "manage tokens";
    case Action::kManageModels: return "manage stored models";
  }
  return "unknown action";
}

std::string HashToken(std::string_view token) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  // One-shot EVP digest; SHA-256 cannot fail for in-memory input short of an allocation failure.
  if (EVP_Digest(token.data(), token.size(), digest, &length, EVP_sha256(), nullptr) != 1) return std::string(64, '0');
  return Hex(digest, length);
}

bool ConstantTimeEquals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  return a.empty() || CRYPTO_memcmp(a.data(), b.data(), a.size()) == 0;
}

absl::StatusOr<std::string> NewRandomToken() {
  unsigned char bytes[32];
  if (RAND_bytes(bytes, sizeof bytes) != 1) return absl::InternalError("token: the OpenSSL random generator failed");
  return Hex(bytes, sizeof bytes);
}

void TokenRegistry::Add(const std::string& hash, Principal principal) {
  const std::string id = hash.substr(0, kTokenIdChars);
  principal.token_id = id;
  std::lock_guard lock(mu_);
  auto [first, last] = by_id_.equal_range(id);
  for (auto it = first; it != last; ++it) {
    if (it->second.hash == hash) {  // hashes from the store or an issue call, not a presented token
      it->second.principal = std::move(principal);
      return;
    }
  }
  by_id_.emplace(id, Entry{hash, std::move(principal)});
}

int TokenRegistry::Revoke(const std::string& hash_prefix) {
  std::lock_guard lock(mu_);
  int removed = 0;
  for (auto it = by_id_.begin(); it != by_id_.end();) {
    if (!hash_prefix.empty() && it->second.hash.compare(0, hash_prefix.size(), hash_prefix) == 0) {
      it = by_id_.erase(it);
      ++removed;
    } else {
      ++it;
    }
  }
  return removed;
}

size_t TokenRegistry::size() const {
  std::lock_guard lock(mu_);
  return by_id_.size();
}

absl::StatusOr<Principal> TokenRegistry::Authenticate(std::string_view token) const {
  if (token.empty()) return absl::UnauthenticatedError("no bearer token presented");
  if (token.size() > kMaxTokenBytes) {
    return absl::UnauthenticatedError(absl::StrCat("bearer token longer than ", kMaxTokenBytes, " bytes"));
  }
  const std::string hash = HashToken(token);
  std::lock_guard lock(mu_);
  // The id is public (see the class comment); the digest is compared in constant time, and every
  // candidate with the id is compared (almost always one: 48-bit ids).
  const Principal* found = nullptr;
  auto [first, last] = by_id_.equal_range(hash.substr(0, kTokenIdChars));
  for (auto it = first; it != last; ++it) {
    if (ConstantTimeEquals(it->second.hash, hash)) found = &it->second.principal;
  }
  if (!found) return absl::UnauthenticatedError("unknown or revoked bearer token");
  return *found;
}

absl::Status Authorize(const Principal& who, Action action, const std::string& camera_id) {
  const auto deny = [&](const std::string& why) {
    return absl::PermissionDeniedError(absl::StrCat("token ", who.token_id, " (role ", RoleName(who.role),
                                                    ") may not ", ActionName(action), why));
  };
  switch (action) {
    case Action::kStream:
      if (who.role != Role::kSensor) return deny(": only sensor tokens stream");
      if (!who.camera_id.empty() && who.camera_id != camera_id) {
        return deny(absl::StrCat(" as camera '", camera_id, "': it is bound to camera '", who.camera_id, "'"));
      }
      return absl::OkStatus();
    case Action::kSubscribe:
    case Action::kReadModel:
      if (who.role == Role::kViewer || who.role == Role::kAdmin) return absl::OkStatus();
      return deny(": only viewer and admin tokens read scene state");
    case Action::kManageCameras:
    case Action::kManageTokens:
    case Action::kManageModels:
      if (who.role == Role::kAdmin) return absl::OkStatus();
      return deny(": only admin tokens do");
  }
  return deny("");
}

}  // namespace ave
