// Large arrays in transparent huge pages, on request (KDSPACE_HUGE_PAGES=1).
//
// The trees' points and order, the joins' cells and k-NN rows and the batches' results run to
// hundreds of MB (1e6 3-D points, k = 10: 160 MB of k-NN rows). In 4 KiB pages such an array costs a
// page fault per 4 KiB on first touch and, read or written out of order, a TLB miss on most accesses;
// in 2 MiB pages both are 512 times fewer. Linux backs an anonymous mapping with huge pages when
// transparent huge pages are `always`, or `madvise` and the mapping asked for them by
// madvise(MADV_HUGEPAGE); and only in ranges aligned to 2 MiB.
//
// Where enabled, arrays of huge_page_threshold bytes and more are mapped here, at an address aligned
// to 2 MiB, and advised before their first touch (HugePageAllocator, HugePageVector<T> for the
// library's own arrays). Arrays a user receives stay std::vector (NeighborLists, pairs): for them
// reserve_in_huge_pages() reserves the room and advises its aligned interior, which a large
// allocation of the C library (a fresh mapping) takes before it is touched. Otherwise (the default;
// `never`; no such file; not Linux) nothing of this runs: the allocation is operator new's and no
// advice is given. The values in the arrays do not depend on the pages, so neither do any answers.
//
// Off unless asked for, because on the virtual machines we measure on it cost more than it saved
// (README, joins): page faults 281k -> 45k for the joins bench at 1e6 points, the single-tree batch
// 8% less user time, the self-join none; but a huge page whose memory the guest had handed back to
// the host (free page reporting) took 3-6 ms to fault in, 4-8x the 512 small faults it replaces, so
// a first call (a fresh process) spent 0.5-1 s more in the kernel, and pairs within r, which touch
// their arrays about once, took 1.5x as long.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>
#define KDSPACE_HAVE_MADVISE 1
#endif

namespace kdspace::detail {

/// The size of a transparent huge page on x86-64 (and arm64 with 4 KiB base pages).
inline constexpr std::size_t huge_page_bytes = std::size_t{2} << 20;

/// Arrays from this size on ask for huge pages: two of them or more, so that at least one aligned
/// huge page lies inside even an unaligned array (reserve_in_huge_pages). Smaller arrays are
/// allocated as before (our reasoning, not a measurement: a mapping of their own and its system
/// calls would cost them about what the few page faults they save do; with huge pages asked for,
/// the joins bench at 2e4 points, whose arrays are all smaller, ran as fast as without).
inline constexpr std::size_t huge_page_threshold = std::size_t{4} << 20;

/// Whether large arrays ask for huge pages: the environment variable KDSPACE_HUGE_PAGES is 1, on
/// Linux with transparent huge pages `always` or `madvise` (/sys/kernel/mm/transparent_hugepage/
/// enabled); read once per process, so an array is freed the way it was allocated even if either
/// changes.
inline bool huge_pages_enabled() {
#if defined(KDSPACE_HAVE_MADVISE)
  static const bool enabled = [] {
    const char* asked = std::getenv("KDSPACE_HUGE_PAGES");
    if (asked == nullptr || std::strcmp(asked, "1") != 0) return false;
    std::FILE* f = std::fopen("/sys/kernel/mm/transparent_hugepage/enabled", "r");
    if (f == nullptr) return false;
    char mode[128] = {};
    const std::size_t got = std::fread(mode, 1, sizeof mode - 1, f);
    std::fclose(f);
    mode[got] = '\0';
    return std::strstr(mode, "[always]") != nullptr || std::strstr(mode, "[madvise]") != nullptr;
  }();
  return enabled;
#else
  return false;
#endif
}

/// Whether an array of `bytes` is mapped by HugePageAllocator (and advised by reserve_in_huge_pages).
inline bool in_huge_pages(std::size_t bytes) { return bytes >= huge_page_threshold && huge_pages_enabled(); }

#if defined(KDSPACE_HAVE_MADVISE)
inline std::size_t base_page_bytes() {
  static const std::size_t bytes = static_cast<std::size_t>(sysconf(_SC_PAGESIZE));
  return bytes;
}

inline std::size_t round_up(std::size_t value, std::size_t multiple) {
  return (value + multiple - 1) / multiple * multiple;
}

/// Asks for huge pages in the 2 MiB-aligned part of [data, data + bytes). Advice only: a refusal
/// (EINVAL where the kernel has no transparent huge pages) changes nothing, so it is ignored.
inline void advise_huge_pages(void* data, std::size_t bytes) {
  const std::uintptr_t begin = round_up(reinterpret_cast<std::uintptr_t>(data), huge_page_bytes);
  const std::uintptr_t end = (reinterpret_cast<std::uintptr_t>(data) + bytes) / huge_page_bytes * huge_page_bytes;
  if (begin < end) (void)madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
}

/// A fresh anonymous mapping of `bytes` (rounded up to base pages) starting at a multiple of 2 MiB,
/// advised for huge pages; its tail beyond the last whole huge page stays in base pages, so it
/// takes no more memory than the array. Throws std::bad_alloc when the system has no room.
inline void* map_in_huge_pages(std::size_t bytes) {
  const std::size_t length = round_up(bytes, base_page_bytes());
  // Room for any alignment, then the parts before and after the aligned range handed back.
  const std::size_t room = length + huge_page_bytes;
  void* mapped = mmap(nullptr, room, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (mapped == MAP_FAILED) throw std::bad_alloc();
  const std::uintptr_t first = reinterpret_cast<std::uintptr_t>(mapped);
  const std::uintptr_t aligned = round_up(first, huge_page_bytes);
  if (aligned > first) munmap(mapped, aligned - first);
  const std::size_t after = first + room - (aligned + length);
  if (after > 0) munmap(reinterpret_cast<void*>(aligned + length), after);
  void* data = reinterpret_cast<void*>(aligned);
  (void)madvise(data, length, MADV_HUGEPAGE);
  return data;
}

inline void unmap_huge_pages(void* data, std::size_t bytes) { munmap(data, round_up(bytes, base_page_bytes())); }
#endif

/// An allocator whose arrays of huge_page_threshold bytes and more lie in huge pages where the system
/// allows (see above); others, and all where it does not, come from operator new. Stateless: any
/// two compare equal, so vectors move and swap their arrays freely.
template <class T>
class HugePageAllocator {
 public:
  using value_type = T;

  HugePageAllocator() noexcept = default;
  template <class U>
  HugePageAllocator(const HugePageAllocator<U>&) noexcept {}

  T* allocate(std::size_t n) {
    if (n > std::numeric_limits<std::size_t>::max() / sizeof(T)) throw std::bad_array_new_length();
#if defined(KDSPACE_HAVE_MADVISE)
    if (in_huge_pages(n * sizeof(T))) return static_cast<T*>(map_in_huge_pages(n * sizeof(T)));
#endif
    return std::allocator<T>().allocate(n);
  }

  void deallocate(T* p, std::size_t n) noexcept {
#if defined(KDSPACE_HAVE_MADVISE)
    if (in_huge_pages(n * sizeof(T))) return unmap_huge_pages(p, n * sizeof(T));
#endif
    std::allocator<T>().deallocate(p, n);
  }

};

template <class T, class U>
bool operator==(const HugePageAllocator<T>&, const HugePageAllocator<U>&) noexcept {
  return true;
}
template <class T, class U>
bool operator!=(const HugePageAllocator<T>&, const HugePageAllocator<U>&) noexcept {
  return false;
}

/// The library's own large arrays.
template <class T>
using HugePageVector = std::vector<T, HugePageAllocator<T>>;

/// Reserves room for n values in a std::vector that a user receives, and asks for huge pages in it
/// before it is touched (for arrays of huge_page_threshold bytes and more, where enabled). The C
/// library maps so large an allocation afresh, but not at a multiple of 2 MiB: up to a huge page at
/// each end stays in base pages.
template <class T, class Allocator>
void reserve_in_huge_pages(std::vector<T, Allocator>& values, std::size_t n) {
  values.reserve(n);
#if defined(KDSPACE_HAVE_MADVISE)
  const std::size_t bytes = values.capacity() * sizeof(T);
  if (in_huge_pages(bytes)) advise_huge_pages(values.data(), bytes);
#endif
}

}  // namespace kdspace::detail
