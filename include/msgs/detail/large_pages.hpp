// include/msgs/detail/large_pages.hpp
// Memory for large arrays in 2 MiB pages where the kernel offers them (transparent huge pages).
// A training step reads the model's rows, the tile lists and the gradient records by index, all
// over arrays of many megabytes: with 4 KiB pages nearly every such read also misses the TLB.
#pragma once

#include <cstddef>
#include <cstdint>
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

/// Blocks from this size on are worth faulting in from every thread (populate_for_write).
inline constexpr std::size_t kPopulateMinBytes = std::size_t(4) << 20;

/// Faults in the pages of [p, p + bytes) for writing, without changing a byte, the large-page
/// pieces spread over the OpenMP threads (madvise(MADV_POPULATE_WRITE), Linux 5.14 on). The kernel
/// zeroes a fresh page when it is first touched; a serial first touch (the value-initialising
/// resize of a grown std::vector, say) leaves all of that to one core while the others wait.
/// Where the kernel refuses, nothing happens and the pages come in when first touched, as
/// before. Blocks under kPopulateMinBytes are left alone.
inline void populate_for_write(void* p, std::size_t bytes) noexcept {
#if defined(__linux__) && defined(MADV_POPULATE_WRITE)
  if (p == nullptr || bytes < kPopulateMinBytes) return;
  constexpr std::uintptr_t kPage = 4096;
  const std::uintptr_t lo = reinterpret_cast<std::uintptr_t>(p) & ~(kPage - 1);
  const std::uintptr_t hi = (reinterpret_cast<std::uintptr_t>(p) + bytes + kPage - 1) & ~(kPage - 1);
  // Pieces end on large-page boundaries, so that each large page is faulted in by one call.
  const std::uintptr_t first_end = (lo / kLargePageBytes + 1) * kLargePageBytes;
  const std::ptrdiff_t pieces = std::ptrdiff_t(1 + (hi > first_end ? (hi - first_end + kLargePageBytes - 1) / kLargePageBytes : 0));
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t k = 0; k < pieces; ++k) {
    const std::uintptr_t a = k == 0 ? lo : first_end + std::uintptr_t(k - 1) * kLargePageBytes;
    const std::uintptr_t b = k == 0 ? (first_end < hi ? first_end : hi) : (a + kLargePageBytes < hi ? a + kLargePageBytes : hi);
    (void)madvise(reinterpret_cast<void*>(a), b - a, MADV_POPULATE_WRITE);
  }
#else
  (void)p;
  (void)bytes;
#endif
}

}  // namespace msgs::detail
