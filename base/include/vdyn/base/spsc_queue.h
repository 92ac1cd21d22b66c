// A bounded, lock-free, single-producer single-consumer queue: the way the 1 kHz thread hands
// work to its publisher without a lock or an allocation. Slots are allocated once, at
// construction; TryPush moves an item into a slot, TryPop moves it out. Neither ever blocks.
#pragma once

#include <atomic>
#include <cstddef>
#include <memory>
#include <new>
#include <utility>

namespace vdyn::base {

template <class T>
class SpscQueue {
 public:
  // Capacity is rounded up to a power of two.
  explicit SpscQueue(std::size_t capacity) {
    std::size_t n = 2;
    while (n < capacity) n *= 2;
    mask_ = n - 1;
    slots_ = std::make_unique<T[]>(n);
  }
  SpscQueue(const SpscQueue&) = delete;
  SpscQueue& operator=(const SpscQueue&) = delete;

  // Producer only. False (and the item untouched) when full.
  [[nodiscard]] bool TryPush(T&& item) {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_cache_ > mask_) {
      tail_cache_ = tail_.load(std::memory_order_acquire);
      if (head - tail_cache_ > mask_) return false;
    }
    slots_[head & mask_] = std::move(item);
    head_.store(head + 1, std::memory_order_release);
    return true;
  }
  // Producer only: a slot to fill in place, or nullptr when full; Commit() publishes it.
  [[nodiscard]] T* Reserve() {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_cache_ > mask_) {
      tail_cache_ = tail_.load(std::memory_order_acquire);
      if (head - tail_cache_ > mask_) return nullptr;
    }
    return &slots_[head & mask_];
  }
  void Commit() { head_.store(head_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }
  // Producer only: how many items fit now.
  [[nodiscard]] std::size_t Room() {
    const std::size_t head = head_.load(std::memory_order_relaxed);
    tail_cache_ = tail_.load(std::memory_order_acquire);
    return mask_ + 1 - (head - tail_cache_);
  }
  // Producer only: the slot `k` places after the next one to fill (k < Room()). The producer may
  // hand such slots to other threads to fill in place; once they are done (and that is visible
  // to the producer), Commit(n) publishes the next n.
  [[nodiscard]] T* Slot(std::size_t k) {
    return &slots_[(head_.load(std::memory_order_relaxed) + k) & mask_];
  }
  void Commit(std::size_t n) {
    head_.store(head_.load(std::memory_order_relaxed) + n, std::memory_order_release);
  }

  // Consumer only. False when empty.
  [[nodiscard]] bool TryPop(T& out) {
    T* front = Front();
    if (front == nullptr) return false;
    out = std::move(*front);
    Pop();
    return true;
  }
  // Consumer only: the oldest item in place (nullptr when empty); Pop() releases it.
  [[nodiscard]] T* Front() {
    const std::size_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_cache_) {
      head_cache_ = head_.load(std::memory_order_acquire);
      if (tail == head_cache_) return nullptr;
    }
    return &slots_[tail & mask_];
  }
  void Pop() { tail_.store(tail_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

  // Either side; a snapshot.
  std::size_t size() const {
    return head_.load(std::memory_order_acquire) - tail_.load(std::memory_order_acquire);
  }
  bool empty() const { return size() == 0; }
  std::size_t capacity() const { return mask_ + 1; }

 private:
  static constexpr std::size_t kLine = 64;
  std::unique_ptr<T[]> slots_;
  std::size_t mask_ = 0;
  alignas(kLine) std::atomic<std::size_t> head_{0};  // written by the producer
  std::size_t tail_cache_ = 0;                         // the producer's view of tail_
  alignas(kLine) std::atomic<std::size_t> tail_{0};  // written by the consumer
  std::size_t head_cache_ = 0;                         // the consumer's view of head_
};

}  // namespace vdyn::base
