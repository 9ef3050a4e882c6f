// tests/test_large_pages.cpp: large arrays in large pages (detail::allocate_large_aware, the
// tile lists' allocator, and the replacement operator new of msgs/large_page_new.hpp, which this
// program includes as the msgs tool does).
#include <doctest/doctest.h>

#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <msgs/detail/overwrite_vector.hpp>
#include <msgs/large_page_new.hpp>

using msgs::detail::kLargePageBytes;

namespace {

bool on_large_page_boundary(const void* p) { return reinterpret_cast<std::uintptr_t>(p) % kLargePageBytes == 0; }

/// The VmFlags line of the mapping that holds `p` in /proc/self/smaps; empty where there is none.
std::string vm_flags_of(const void* p) {
  std::ifstream smaps("/proc/self/smaps");
  const auto a = reinterpret_cast<std::uintptr_t>(p);
  std::string line;
  bool inside = false;
  while (std::getline(smaps, line)) {
    std::uintptr_t lo = 0, hi = 0;
    char dash = 0;
    std::istringstream head(line);
    if (head >> std::hex >> lo >> dash >> hi && dash == '-') {
      inside = lo <= a && a < hi;
      continue;
    }
    if (inside && line.rfind("VmFlags:", 0) == 0) return line;
  }
  return {};
}

/// Whether this kernel has transparent huge pages at all (else madvise refuses the advice).
bool kernel_has_thp() {
  std::ifstream f("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string mode;
  return std::getline(f, mode) && mode.find("[never]") == std::string::npos;
}

}  // namespace

TEST_CASE("allocate_large_aware: large blocks on large-page boundaries, advised; small ones from malloc") {
  for (const std::size_t bytes : {kLargePageBytes, kLargePageBytes + 1, std::size_t(9) << 20}) {
    CAPTURE(bytes);
    auto* p = static_cast<unsigned char*>(msgs::detail::allocate_large_aware(bytes));
    REQUIRE(p != nullptr);
    CHECK(on_large_page_boundary(p));
    p[0] = 1;
    p[bytes - 1] = 2;  // the whole block is ours
    CHECK(p[0] + p[bytes - 1] == 3);
#if defined(__linux__)
    if (kernel_has_thp()) {
      const std::string flags = vm_flags_of(p);
      CAPTURE(flags);
      CHECK(flags.find(" hg") != std::string::npos);  // MADV_HUGEPAGE took
    }
#endif
    std::free(p);
  }
  for (const std::size_t bytes : {std::size_t(0), std::size_t(1), std::size_t(4096), kLargePageBytes - 1}) {
    CAPTURE(bytes);
    void* p = msgs::detail::allocate_large_aware(bytes);
    CHECK(p != nullptr);
    std::free(p);
  }
}

TEST_CASE("tile-list buffers (OverwriteVector) grow into large pages and keep their values' rules") {
  msgs::detail::OverwriteVector<float> v;
  msgs::detail::resize_for_overwrite(v, 100);
  CHECK(v.size() == 100);
  msgs::detail::resize_for_overwrite(v, std::size_t(3) << 20);  // 12 MiB
  REQUIRE(v.size() == std::size_t(3) << 20);
  CHECK(on_large_page_boundary(v.data()));
  for (std::size_t i = 0; i < v.size(); i += 4096) v[i] = float(i);
  v.push_back(7.0f);  // growing copies what is there
  CHECK(v[4096] == 4096.0f);
  CHECK(v.back() == 7.0f);
  msgs::detail::OverwriteVector<float>().swap(v);
  CHECK(v.capacity() == 0);
}

TEST_CASE("the replacement operator new: large arrays of the program in large pages") {
  std::vector<float> model(std::size_t(2) << 20, 1.0f);  // 8 MiB, as a model's band planes
  std::vector<float> small(1000, 2.0f);
  CHECK(model.back() == 1.0f);
  CHECK(small.front() == 2.0f);
  auto array = std::make_unique<double[]>(std::size_t(1) << 20);  // new[] and delete[]
  CHECK(array[12345] == 0.0);
#if !defined(MSGS_SANITIZED_ALLOCATOR)  // (the sanitizers' own operators are in place there)
  CHECK(on_large_page_boundary(model.data()));
  CHECK(on_large_page_boundary(array.get()));
  // An impossible size: nothrow new gives nullptr, new throws std::bad_alloc.
  volatile std::size_t impossible = std::size_t(-1) / 2;
  void* none = ::operator new(impossible, std::nothrow);
  CHECK(none == nullptr);
  CHECK(::operator new[](impossible, std::nothrow) == nullptr);
  CHECK_THROWS_AS((void)::operator new(impossible), std::bad_alloc);
#endif
}
