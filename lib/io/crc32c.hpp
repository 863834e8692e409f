// CRC-32C (Castagnoli; the checksum of iSCSI, ext4 and Btrfs metadata): the checksum of every part of
// an index file. A CRC detects every error burst of up to 32 bits, so any one damaged byte, or any run
// of damaged bytes up to 4 long, is always caught; longer damage escapes with probability 2^-32.
#pragma once

#include <cstddef>
#include <cstdint>

namespace kdspace::io::detail {

/// The CRC-32C of `size` bytes (initial value and final xor 0xFFFFFFFF, reflected; the CRC-32C of
/// "123456789" is 0xE3069283). Uses the SSE4.2 crc32 instruction where the processor has it.
std::uint32_t crc32c(const void* data, std::size_t size);

/// The CRC-32C of A followed by `size` more bytes, from crc32c(A) (0 for an empty A): lets a reader
/// checksum a range piece by piece as it goes.
std::uint32_t crc32c_extend(std::uint32_t crc, const void* data, std::size_t size);

/// The CRC-32C of A followed by B, from crc32c(A), crc32c(B) and B's length: crc(A) times
/// x^(8 |B|) mod P, plus crc(B) (the initial and final inversions cancel). Lets several threads check
/// parts of one range.
std::uint32_t crc32c_combine(std::uint32_t crc_a, std::uint32_t crc_b, std::size_t length_b);

/// The same checksum from the lookup tables alone (for tests of the fast path).
std::uint32_t crc32c_portable(const void* data, std::size_t size);

/// crc32c_combine by bitwise multiplications alone (for tests of the pclmul path).
std::uint32_t crc32c_combine_portable(std::uint32_t crc_a, std::uint32_t crc_b, std::size_t length_b);

/// Whether crc32c() runs on the processor's crc32 instruction (else on lookup tables).
bool crc32c_in_hardware();

}  // namespace kdspace::io::detail
