// write_png with libpng. libpng reports errors by longjmp to the setjmp point; the function that
// calls setjmp (write_rows) therefore holds only plain C data, and no C++ object with a destructor
// lives across the jump.
#include "png_writer.hpp"

#include <png.h>

#include <cerrno>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "kdspace/error.hpp"

namespace kdspace::cli {

namespace {

/// Returns nullptr on success, else a static description of the failure.
const char* write_rows(std::FILE* file, png_bytep* rows, png_uint_32 width, png_uint_32 height) {
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  if (!png) return "libpng: out of memory";
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_write_struct(&png, nullptr);
    return "libpng: out of memory";
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return "libpng could not write the image";
  }
  png_init_io(png, file);
  png_set_IHDR(png, info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  png_write_image(png, rows);
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return nullptr;
}

}  // namespace

void write_png(const std::string& path, const std::uint8_t* rgb, std::size_t width, std::size_t height) {
  if (width == 0 || height == 0 || width > 0x7fffffffu || height > 0x7fffffffu)
    throw Error(path + ": image size " + std::to_string(width) + " x " + std::to_string(height) +
                " cannot be written");
  std::vector<png_bytep> rows(height);
  for (std::size_t y = 0; y < height; ++y) rows[y] = const_cast<png_bytep>(rgb + y * width * 3);
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (!file) throw Error(path + ": cannot open for writing: " + std::strerror(errno));
  const char* problem =
      write_rows(file, rows.data(), static_cast<png_uint_32>(width), static_cast<png_uint_32>(height));
  const bool closed = std::fclose(file) == 0;
  if (problem) throw Error(path + ": " + problem);
  if (!closed) throw Error(path + ": write error: " + std::strerror(errno));
}

}  // namespace kdspace::cli
