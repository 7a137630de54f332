#pragma once
// A single-writer, many-reader sequence lock: the haptic loop, the tissue model's update thread
// and the display hand states to each other through it without locks or allocation.

#include <array>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <type_traits>

namespace organsmith {

/// Single-writer, many-reader sequence lock for a trivially copyable value. write() never waits;
/// read() retries while a write is in progress (a few hundred ns at most), so neither side takes a
/// lock or allocates. The value is held in atomic words, so there is no data race.
template <class T>
class SeqLock {
  static_assert(std::is_trivially_copyable_v<T>, "SeqLock holds trivially copyable values");

 public:
  SeqLock() { write(T{}); }
  explicit SeqLock(const T& v) { write(v); }

  /// Only one thread may write.
  void write(const T& v) noexcept {
    std::uint64_t buf[kWords] = {};
    std::memcpy(buf, &v, sizeof(T));
    const std::uint64_t s = seq_.load(std::memory_order_relaxed);
    seq_.store(s + 1, std::memory_order_relaxed);
    std::atomic_thread_fence(std::memory_order_release);
    for (std::size_t i = 0; i < kWords; ++i) words_[i].store(buf[i], std::memory_order_relaxed);
    seq_.store(s + 2, std::memory_order_release);
  }

  T read() const noexcept {
    std::uint64_t buf[kWords];
    while (true) {
      const std::uint64_t s0 = seq_.load(std::memory_order_acquire);
      if (s0 & 1) continue;
      for (std::size_t i = 0; i < kWords; ++i) buf[i] = words_[i].load(std::memory_order_relaxed);
      std::atomic_thread_fence(std::memory_order_acquire);
      if (seq_.load(std::memory_order_relaxed) == s0) break;
    }
    T v;
    std::memcpy(&v, buf, sizeof(T));
    return v;
  }

 private:
  static constexpr std::size_t kWords = (sizeof(T) + 7) / 8;
  std::atomic<std::uint64_t> seq_{0};
  std::array<std::atomic<std::uint64_t>, kWords> words_{};
};

}  // namespace organsmith
