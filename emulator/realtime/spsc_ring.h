#pragma once
/// A bounded lock-free single-producer / single-consumer ring of trivially copyable values.
/// The storage is allocated once in the constructor; TryPush/TryPop never allocate, never block
/// and never throw, so they may be called from a real-time thread.
///
/// Thread-safety: exactly one thread may call TryPush and exactly one (other) thread TryPop at
/// the same time; capacity() and SizeApprox() from any thread. Push publishes with release,
/// pop reads with acquire: everything the producer wrote into the value before TryPush is
/// visible to the consumer after TryPop.

#include <atomic>
#include <cstddef>
#include <memory>
#include <stdexcept>
#include <type_traits>

namespace wheelhil::emulator::realtime {

template <typename T>
class SpscRing {
  static_assert(std::is_trivially_copyable_v<T>, "SpscRing holds trivially copyable values");

 public:
  /// Holds `capacity` values (rounded up to a power of two, at least 2). Throws
  /// std::invalid_argument for 0 or a capacity above 2^30.
  explicit SpscRing(std::size_t capacity) {
    if (capacity == 0 || capacity > (std::size_t{1} << 30)) {
      throw std::invalid_argument("SpscRing: capacity must be in 1..2^30");
    }
    std::size_t n = 2;
    while (n < capacity) n <<= 1;
    mask_ = n - 1;
    slots_ = std::make_unique<T[]>(n);
  }
  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  /// Producer side. False when the ring is full (nothing written).
  [[nodiscard]] bool TryPush(const T& value) noexcept {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    if (tail - cached_head_ > mask_) {
      cached_head_ = head_.load(std::memory_order_acquire);
      if (tail - cached_head_ > mask_) return false;
    }
    slots_[tail & mask_] = value;
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  /// Consumer side. False when the ring is empty (`out` untouched).
  [[nodiscard]] bool TryPop(T& out) noexcept {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head == cached_tail_) {
      cached_tail_ = tail_.load(std::memory_order_acquire);
      if (head == cached_tail_) return false;
    }
    out = slots_[head & mask_];
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  std::size_t capacity() const noexcept { return mask_ + 1; }
  /// Values in the ring at some instant during the call.
  std::size_t SizeApprox() const noexcept {
    const std::size_t head = head_.load(std::memory_order_acquire);
    const std::size_t tail = tail_.load(std::memory_order_acquire);
    return tail - head;
  }

 private:
  std::unique_ptr<T[]> slots_;
  std::size_t mask_ = 1;
  alignas(64) std::atomic<std::size_t> head_{0};  ///< Next slot to pop (written by the consumer).
  alignas(64) std::atomic<std::size_t> tail_{0};  ///< Next slot to push (written by the producer).
  alignas(64) std::size_t cached_head_ = 0;       ///< Producer's last view of head_.
  alignas(64) std::size_t cached_tail_ = 0;       ///< Consumer's last view of tail_.
};

}  // namespace wheelhil::emulator::realtime
