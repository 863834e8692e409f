// write_png: an 8-bit RGB image to a PNG file, with libpng.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace kdspace::cli {

/// Writes width x height pixels of 3 bytes (R, G, B), rows from the top. Throws kdspace::Error
/// "PATH: what went wrong" when the file cannot be written.
void write_png(const std::string& path, const std::uint8_t* rgb, std::size_t width, std::size_t height);

}  // namespace kdspace::cli
