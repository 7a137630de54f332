#pragma once
// Allocator for voxel buffers (hundreds of MB): no zero-fill on resize. A CT volume is always
// overwritten right after allocation, and zeroing 300 MB on one thread costs more than
// decoding it on two (the first touch then happens in the parallel decoder).

#include <cstddef>
#include <new>
#include <type_traits>
#include <vector>

namespace organsmith {

/// Default-initialising allocator: `resize(n)` leaves new elements of trivial types
/// uninitialised (use `assign(n, value)` when zeros are wanted).
template <typename T>
struct LargeBufferAllocator {
  using value_type = T;
  LargeBufferAllocator() = default;
  template <typename U>
  LargeBufferAllocator(const LargeBufferAllocator<U>&) noexcept {}

  T* allocate(std::size_t n);
  void deallocate(T* p, std::size_t n) noexcept;

  template <typename U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;  // default-init: no zeroing for trivial types
  }
  template <typename U, typename... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }

  template <typename U>
  bool operator==(const LargeBufferAllocator<U>&) const noexcept { return true; }
};

void* allocate_large_buffer(std::size_t bytes);
void free_large_buffer(void* p, std::size_t bytes) noexcept;

template <typename T>
T* LargeBufferAllocator<T>::allocate(std::size_t n) {
  return static_cast<T*>(allocate_large_buffer(n * sizeof(T)));
}
template <typename T>
void LargeBufferAllocator<T>::deallocate(T* p, std::size_t n) noexcept {
  free_large_buffer(p, n * sizeof(T));
}

/// A voxel buffer.
template <typename T>
using VoxelBuffer = std::vector<T, LargeBufferAllocator<T>>;

}  // namespace organsmith
