// include/msgs/large_page_new.hpp
// Replacement global operator new / delete that put large blocks (2 MiB and more) in large pages
// (detail::allocate_large_aware). Include this header in exactly ONE source file of a program
// (the one with main): it defines, not declares, the replaceable allocation functions, so a
// second inclusion is a link error. Every std::vector of the program, the model's arrays and Adam's
// moments included, then gets large pages where the kernel offers them (transparent huge pages in
// "madvise" mode need the advice; in "always" mode this changes nothing).
//
// Side by side on a 2-core Sapphire Rapids VM (THP "madvise"), `bench_train_step` at 1M Gaussians
// and 1280x960 spends most of a step in binning and the blend backward, reading tile lists, splats
// and records by index: see the README ("Training step") for the numbers.
//
// Left out under AddressSanitizer, ThreadSanitizer and MemorySanitizer, whose own operators check
// that new pairs with delete and new[] with delete[].
#pragma once

#include <cstdlib>
#include <new>

#include "msgs/detail/large_pages.hpp"

#if defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || __has_feature(memory_sanitizer)
#define MSGS_SANITIZED_ALLOCATOR 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define MSGS_SANITIZED_ALLOCATOR 1
#endif

#ifndef MSGS_SANITIZED_ALLOCATOR
// The aligned forms (std::align_val_t) keep the standard library's own pair.
void* operator new(std::size_t n) {
  for (;;) {
    if (void* p = msgs::detail::allocate_large_aware(n)) return p;
    const std::new_handler h = std::get_new_handler();
    if (!h) throw std::bad_alloc();
    h();
  }
}
void* operator new[](std::size_t n) { return ::operator new(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return ::operator new(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, const std::nothrow_t& tag) noexcept { return ::operator new(n, tag); }
// Everything above comes from malloc or posix_memalign, so free releases it. GCC, seeing free
// inlined where a new-expression's pointer is deleted, would warn of a mismatch.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
#endif
