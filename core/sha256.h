#pragma once
// SHA-256 (FIPS 180-4) for output digests in the run manifest and input digests. The hashing is
// Debian's nettle library; its types stay in core/sha256.cpp.

#include <filesystem>
#include <memory>
#include <string>
#include <string_view>

namespace organsmith {

/// Incremental SHA-256.
class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(Sha256&&) noexcept;
  Sha256& operator=(Sha256&&) noexcept;
  void update(const void* data, std::size_t bytes);
  void update(std::string_view s) { update(s.data(), s.size()); }
  /// Finishes and returns the digest as 64 lower-case hex characters. Call once.
  std::string hex_digest();

 private:
  struct State;  // nettle's sha256_ctx
  std::unique_ptr<State> state_;
};

/// Hex SHA-256 of a byte string.
std::string sha256_hex(std::string_view bytes);
/// Hex SHA-256 of a file's contents; throws InputError when it cannot be read.
std::string sha256_file(const std::filesystem::path& path);

}  // namespace organsmith
