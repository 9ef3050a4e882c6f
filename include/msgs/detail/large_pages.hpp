// include/msgs/detail/large_pages.hpp
// Memory for large arrays in 2 MiB pages where the kernel offers them (transparent huge pages).
// A training step reads the model's rows, the tile lists and the gradient records by index, all
// over arrays of many megabytes: with 4 KiB pages nearly every such read also misses the TLB.
#pragma once

#include <cstddef>
#include <cstdlib>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace msgs::detail {

/// Size of a transparent huge page on x86-64 and most arm64 kernels.
inline constexpr std::size_t kLargePageBytes = std::size_t(2) << 20;

/// `bytes` of uninitialised memory, nullptr when there is none; release with std::free. From
/// kLargePageBytes on, the block starts on a large-page boundary and the kernel is advised to back
/// it with large pages (madvise(MADV_HUGEPAGE): what Linux needs where transparent huge pages are
/// in "madvise" mode, Debian's default; elsewhere the advice changes nothing). Smaller blocks come
/// from malloc. At most one large page of the block's tail may be backed beyond `bytes`.
inline void* allocate_large_aware(std::size_t bytes) noexcept {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  if (bytes >= kLargePageBytes) {
    void* p = nullptr;
    if (posix_memalign(&p, kLargePageBytes, bytes) != 0) return nullptr;
    (void)madvise(p, bytes, MADV_HUGEPAGE);  // advice: if refused, the pages are small ones
    return p;
  }
#endif
  return std::malloc(bytes > 0 ? bytes : 1);
}

}  // namespace msgs::detail
