#include "core/sha256.h"

#include "core/errors.h"

#include <nettle/sha2.h>

#include <fstream>
#include <vector>

namespace organsmith {

struct Sha256::State {
  sha256_ctx ctx;
};

Sha256::Sha256() : state_(std::make_unique<State>()) { sha256_init(&state_->ctx); }
Sha256::~Sha256() = default;
Sha256::Sha256(Sha256&&) noexcept = default;
Sha256& Sha256::operator=(Sha256&&) noexcept = default;

void Sha256::update(const void* data, std::size_t bytes) {
  sha256_update(&state_->ctx, bytes, static_cast<const std::uint8_t*>(data));
}

std::string Sha256::hex_digest() {
  std::uint8_t digest[SHA256_DIGEST_SIZE];
  sha256_digest(&state_->ctx, SHA256_DIGEST_SIZE, digest);
  static const char* hex = "0123456789abcdef";
  std::string out;
  out.reserve(2 * SHA256_DIGEST_SIZE);
  for (const std::uint8_t b : digest) out.push_back(hex[b >> 4]), out.push_back(hex[b & 0xf]);
  return out;
}

std::string sha256_hex(std::string_view bytes) {
  Sha256 s;
  s.update(bytes);
  return s.hex_digest();
}

std::string sha256_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(ExitCode::input_not_found, "cannot open file to hash", path);
  Sha256 s;
  std::vector<char> buf(1 << 20);
  while (in) {
    in.read(buf.data(), std::streamsize(buf.size()));
    s.update(buf.data(), std::size_t(in.gcount()));
  }
  return s.hex_digest();
}

}  // namespace organsmith
