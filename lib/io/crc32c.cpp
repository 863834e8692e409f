// CRC-32C in software (eight lookup tables, eight bytes a step) and with SSE4.2's crc32 instruction
// (three independent streams, combined by polynomial arithmetic, to hide the instruction's latency).
//
// Notation: the CRC register is kept reflected (bit 31 holds the coefficient of x^0, bit 0 that of
// x^31), as the crc32 instruction keeps it. update(c, bytes) runs the register over the bytes with
// no initial or final inversion; crc32c(bytes) = ~update(~0, bytes).
#include "crc32c.hpp"

#include <array>
#include <cstring>

#if defined(__x86_64__)
#include <nmmintrin.h>
#endif

namespace kdspace::io::detail {
namespace {

constexpr std::uint32_t poly = 0x82F63B78u;  // x^32 + x^28 + x^27 + ... + 1, reflected, without x^32

// tables[0][b]: the register after running a zero register over byte b; tables[j][b]: the same
// byte followed by j zero bytes. Eight of them fold eight bytes in one step.
constexpr std::array<std::array<std::uint32_t, 256>, 8> make_tables() {
  std::array<std::array<std::uint32_t, 256>, 8> t{};
  for (std::uint32_t b = 0; b < 256; ++b) {
    std::uint32_t c = b;
    for (int bit = 0; bit < 8; ++bit) c = (c & 1u) ? (c >> 1) ^ poly : c >> 1;
    t[0][b] = c;
  }
  for (std::size_t j = 1; j < 8; ++j)
    for (std::uint32_t b = 0; b < 256; ++b) t[j][b] = (t[j - 1][b] >> 8) ^ t[0][t[j - 1][b] & 0xffu];
  return t;
}
constexpr auto tables = make_tables();

std::uint32_t update_software(std::uint32_t c, const unsigned char* p, std::size_t n) {
  for (; n >= 8; n -= 8, p += 8) {
    std::uint64_t word;
    std::memcpy(&word, p, 8);  // little-endian: the first byte is the lowest
    word ^= c;
    c = tables[7][word & 0xff] ^ tables[6][(word >> 8) & 0xff] ^ tables[5][(word >> 16) & 0xff] ^
        tables[4][(word >> 24) & 0xff] ^ tables[3][(word >> 32) & 0xff] ^ tables[2][(word >> 40) & 0xff] ^
        tables[1][(word >> 48) & 0xff] ^ tables[0][word >> 56];
  }
  for (; n > 0; --n, ++p) c = (c >> 8) ^ tables[0][(c ^ *p) & 0xffu];
  return c;
}

// a(x) * b(x) mod P(x), reflected. Walks a's coefficients from x^0 up while b is multiplied by x.
std::uint32_t multiply(std::uint32_t a, std::uint32_t b) {
  std::uint32_t product = 0;
  for (std::uint32_t bit = 0x80000000u; bit != 0; bit >>= 1) {
    if (a & bit) product ^= b;
    b = (b & 1u) ? (b >> 1) ^ poly : b >> 1;
  }
  return product;
}

// x^(8 * bytes) mod P: multiplying a register by it appends that many zero bytes.
std::uint32_t zeros_operator(std::size_t bytes) {
  std::uint32_t result = 0x80000000u;  // x^0
  std::uint32_t power = 0x00800000u;   // x^8: one zero byte
  for (; bytes > 0; bytes >>= 1) {
    if (bytes & 1u) result = multiply(result, power);
    power = multiply(power, power);
  }
  return result;
}

#if defined(__x86_64__)
// Bytes per stream in one round of the three-stream loop.
constexpr std::size_t stream_bytes = 4096;

__attribute__((target("sse4.2"))) std::uint64_t run_words(std::uint64_t c, const unsigned char* p,
                                                          std::size_t words) {
  for (std::size_t i = 0; i < words; ++i) {
    std::uint64_t w;
    std::memcpy(&w, p + 8 * i, 8);
    c = _mm_crc32_u64(c, w);
  }
  return c;
}

__attribute__((target("sse4.2"))) std::uint32_t update_hardware(std::uint32_t c, const unsigned char* p,
                                                                std::size_t n) {
  // The crc32 instruction has a latency of 3 cycles and a throughput of 1: three independent
  // streams over consecutive blocks keep it busy. update(c, A B C) =
  // shift(shift(update(c, A), |B|) ^ update(0, B), |C|) ^ update(0, C).
  static const std::uint32_t shift = zeros_operator(stream_bytes);
  std::uint64_t c0 = c;
  for (; n >= 3 * stream_bytes; n -= 3 * stream_bytes, p += 3 * stream_bytes) {
    std::uint64_t c1 = 0, c2 = 0;
    for (std::size_t i = 0; i < stream_bytes; i += 8) {
      std::uint64_t w0, w1, w2;
      std::memcpy(&w0, p + i, 8);
      std::memcpy(&w1, p + stream_bytes + i, 8);
      std::memcpy(&w2, p + 2 * stream_bytes + i, 8);
      c0 = _mm_crc32_u64(c0, w0);
      c1 = _mm_crc32_u64(c1, w1);
      c2 = _mm_crc32_u64(c2, w2);
    }
    std::uint32_t joined = multiply(static_cast<std::uint32_t>(c0), shift) ^ static_cast<std::uint32_t>(c1);
    joined = multiply(joined, shift) ^ static_cast<std::uint32_t>(c2);
    c0 = joined;
  }
  c0 = run_words(c0, p, n / 8);
  p += n / 8 * 8;
  std::uint32_t r = static_cast<std::uint32_t>(c0);
  for (std::size_t i = 0; i < n % 8; ++i) r = _mm_crc32_u8(r, p[i]);
  return r;
}

bool has_sse42() {
  static const bool yes = __builtin_cpu_supports("sse4.2");
  return yes;
}
#endif

}  // namespace

std::uint32_t crc32c(const void* data, std::size_t size) {
  return crc32c_extend(0, data, size);
}

std::uint32_t crc32c_extend(std::uint32_t crc, const void* data, std::size_t size) {
  const auto* p = static_cast<const unsigned char*>(data);
#if defined(__x86_64__)
  if (has_sse42()) return ~update_hardware(~crc, p, size);
#endif
  return ~update_software(~crc, p, size);
}

std::uint32_t crc32c_combine(std::uint32_t crc_a, std::uint32_t crc_b, std::size_t length_b) {
  return multiply(crc_a, zeros_operator(length_b)) ^ crc_b;
}

std::uint32_t crc32c_portable(const void* data, std::size_t size) {
  return ~update_software(0xFFFFFFFFu, static_cast<const unsigned char*>(data), size);
}

bool crc32c_in_hardware() {
#if defined(__x86_64__)
  return has_sse42();
#else
  return false;
#endif
}

}  // namespace kdspace::io::detail
