// include/msgs/detail/overwrite_vector.hpp
// Vectors for per-frame buffers that a pass overwrites whole before anything reads them (tile
// lists, gradient records): growing one neither fills the new values nor copies the old ones.
#pragma once

#include <cstddef>
#include <cstdlib>
#include <limits>
#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

#include "msgs/detail/large_pages.hpp"

namespace msgs::detail {

/// std::allocator whose value-less construct() default-initialises: resize() of a vector of
/// trivial values with it leaves the new values unset instead of zeroing them. Its storage comes
/// from detail::allocate_large_aware (large pages from 2 MiB on): these buffers are the tile
/// lists and gradient records, read and written by index.
template <class T>
struct NoFillAllocator : std::allocator<T> {
  static_assert(alignof(T) <= alignof(std::max_align_t), "malloc's alignment");
  using value_type = T;
  NoFillAllocator() noexcept = default;
  template <class U>
  NoFillAllocator(const NoFillAllocator<U>&) noexcept {}
  template <class U>
  struct rebind {
    using other = NoFillAllocator<U>;
  };
  T* allocate(std::size_t n) {
    if (n > std::numeric_limits<std::size_t>::max() / sizeof(T)) throw std::bad_array_new_length();
    void* p = allocate_large_aware(n * sizeof(T));
    if (!p) throw std::bad_alloc();
    return static_cast<T*>(p);
  }
  void deallocate(T* p, std::size_t) noexcept { std::free(p); }
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... A>
  void construct(U* p, A&&... a) {
    ::new (static_cast<void*>(p)) U(std::forward<A>(a)...);
  }
};

/// A vector for a buffer whose every value is written before it is read.
template <class T>
using OverwriteVector = std::vector<T, NoFillAllocator<T>>;

/// Size `v` to `n` values for a pass that writes all of them: where the storage must grow, the
/// old values are dropped instead of copied and half as much again is reserved, so that the next
/// calls, a little larger, do not reallocate again. An OverwriteVector is not filled either: its
/// new pages are first touched by the pass that writes them (in parallel), not by a serial copy
/// and fill here. (Any std::vector works; one with the standard allocator is zero-filled, after
/// its new pages were faulted in by every thread.)
template <class T, class A>
void resize_for_overwrite(std::vector<T, A>& v, std::size_t n) {
  if (n > v.capacity()) {
    std::vector<T, A>().swap(v);
    v.reserve(n + n / 2);
    // A vector that fills its new values fills them from this thread: fault their pages in from
    // every thread first (populate_for_write), so that the kernel's zeroing of them is shared.
    if constexpr (!std::is_same_v<A, NoFillAllocator<T>>) populate_for_write(v.data(), n * sizeof(T));
  }
  v.resize(n);
}

}  // namespace msgs::detail
