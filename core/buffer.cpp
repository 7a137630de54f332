#include "core/buffer.h"

#include <sys/mman.h>

#include <cstdlib>

namespace organsmith {

namespace {
constexpr std::size_t kHugePage = std::size_t(2) << 20;
}

void* allocate_large_buffer(std::size_t bytes) {
  if (bytes == 0) bytes = 1;
  if (bytes < kHugePage) {
    void* p = std::malloc(bytes);
    if (!p) throw std::bad_alloc();
    return p;
  }
  const std::size_t rounded = (bytes + kHugePage - 1) / kHugePage * kHugePage;
  void* p = std::aligned_alloc(kHugePage, rounded);
  if (!p) throw std::bad_alloc();
  madvise(p, rounded, MADV_HUGEPAGE);  // advice only: failure is harmless
  return p;
}

void free_large_buffer(void* p, std::size_t) noexcept { std::free(p); }

}  // namespace organsmith
