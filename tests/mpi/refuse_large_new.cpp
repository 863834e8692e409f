// Loaded with LD_PRELOAD into one rank of the fault tests (mpi_cli_tests.sh): operator new refuses
// every request above KDSPACE_TEST_NEW_LIMIT bytes with std::bad_alloc, as it does when memory runs
// out, so that the test runs out of memory at once, on one rank, without using any. MPI itself
// allocates with malloc and is not affected.
#include <cstdint>
#include <cstdlib>
#include <new>

namespace {

std::size_t limit() {
  static const std::size_t bytes = [] {
    const char* text = std::getenv("KDSPACE_TEST_NEW_LIMIT");
    return text ? static_cast<std::size_t>(std::strtoull(text, nullptr, 10)) : SIZE_MAX;
  }();
  return bytes;
}

}  // namespace

void* operator new(std::size_t n) {
  if (n > limit()) throw std::bad_alloc();
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  return operator new(n);
}
void operator delete(void* p) noexcept {
  std::free(p);
}
void operator delete[](void* p) noexcept {
  std::free(p);
}
void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::size_t) noexcept {
  std::free(p);
}
