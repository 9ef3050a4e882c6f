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

#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>
#endif

namespace test_large_pages {
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

#if defined(__linux__)
namespace {
/// Pages of [p, p + bytes) that are resident, by mincore.
std::size_t resident_pages(const void* p, std::size_t bytes) {
  const std::uintptr_t page = std::uintptr_t(sysconf(_SC_PAGESIZE));
  const std::uintptr_t lo = reinterpret_cast<std::uintptr_t>(p) & ~(page - 1);
  const std::size_t len = reinterpret_cast<std::uintptr_t>(p) + bytes - lo;
  std::vector<unsigned char> vec((len + page - 1) / page);
  if (mincore(reinterpret_cast<void*>(lo), len, vec.data()) != 0) return 0;
  std::size_t n = 0;
  for (unsigned char c : vec) n += c & 1;
  return n;
}
}  // namespace
#endif

TEST_CASE("populate_for_write faults a block in without changing a byte; a grown vector still reads zeros") {
  const std::size_t bytes = (std::size_t(9) << 20) + 123;
  auto* p = static_cast<unsigned char*>(msgs::detail::allocate_large_aware(bytes));
  REQUIRE(p != nullptr);
#if defined(__linux__) && defined(MADV_POPULATE_WRITE)
  // A fresh block is not resident yet; where this kernel has MADV_POPULATE_WRITE (5.14 on),
  // populating makes all of it resident.
  const std::size_t page = std::size_t(sysconf(_SC_PAGESIZE));
  void* probe = mmap(nullptr, page, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  REQUIRE(probe != MAP_FAILED);
  const bool supported = madvise(probe, page, MADV_POPULATE_WRITE) == 0;
  munmap(probe, page);
  msgs::detail::populate_for_write(p + 5, bytes - 5);  // an unaligned start
  if (supported) CHECK(resident_pages(p, bytes) == (bytes + page - 1) / page);
#endif
  for (std::size_t i = 0; i < bytes; i += 997) p[i] = static_cast<unsigned char>(i * 7 + 1);
  msgs::detail::populate_for_write(p, bytes);  // again, on written pages
  std::size_t changed = 0;
  for (std::size_t i = 0; i < bytes; i += 997) changed += p[i] != static_cast<unsigned char>(i * 7 + 1);
  CHECK(changed == 0);
  std::free(p);

  std::vector<float> v(10, 3.0f);
  msgs::detail::resize_for_overwrite(v, std::size_t(3) << 20);  // grows: old values dropped, new ones zero
  REQUIRE(v.size() == std::size_t(3) << 20);
  std::size_t nonzero = 0;
  for (const float x : v) nonzero += x != 0.0f;
  CHECK(nonzero == 0);
}

}  // namespace test_large_pages
