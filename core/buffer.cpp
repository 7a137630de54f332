#include "core/buffer.h"

#include <cstdlib>

namespace organsmith {

// Transparent huge pages were tried here (2 MiB alignment + MADV_HUGEPAGE): they cut page
// faults on an idle machine, but with the kernel's default "defrag=madvise" policy every fault
// may compact memory synchronously, and under load a 300 MB volume then took minutes to
// allocate. Plain malloc keeps allocation time predictable.
void* allocate_large_buffer(std::size_t bytes) {
  void* p = std::malloc(bytes == 0 ? 1 : bytes);
  if (!p) throw std::bad_alloc();
  return p;
}

void free_large_buffer(void* p, std::size_t) noexcept { std::free(p); }

}  // namespace organsmith
