// Image descriptors for the forest benchmark: dense, upright SIFT-like descriptors (128-D) of
// photographs, computed here.
//
// The photographs are those Debian ships with scikit-image (package python3-skimage, folder
// skimage/data); bench/run_all.sh unpacks that package's files into the build folder (no Python
// is needed or run). base_photos are the base set, and query_photo (the right view of a stereo
// pair whose left view is in the base) gives the queries: matching descriptors of one view of a
// scene against a collection that holds the other view, the usual job of image descriptor search.
//
// A descriptor. Each photo is read as gray levels in [0, 1] and smoothed (Gaussian, sigma 1); each
// further octave is smoothed again (sigma 1.6) and halved. On every octave, keypoints lie on a grid
// of `stride` pixels; each has a 16 x 16 pixel window split into 4 x 4 cells. The gradient of every
// window pixel (central differences) adds its magnitude, weighted by a Gaussian of the window's
// half width, to an 8-bin orientation histogram per cell, shared with linear weights between the
// two nearest cells along each axis and the two nearest orientation bins. The 128 sums are
// normalised to unit length, clipped at 0.2 and normalised again, then scaled by 512 and rounded to
// integers at most 255 (the usual byte form of such descriptors). Windows of mean gradient below
// min_gradient (flat sky, walls) give no descriptor.
#pragma once

#include <png.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

namespace kdspace_bench {

inline constexpr std::size_t image_descriptor_dim = 128;

inline const std::vector<std::string>& base_photos() {
  static const std::vector<std::string> names = {"astronaut", "brick", "camera", "cell", "chelsea", "coffee",
                                                 "coins", "grass", "gravel", "ihc", "moon", "motorcycle_left"};
  return names;
}
inline const char* query_photo() { return "motorcycle_right"; }

struct GrayImage {
  int width = 0, height = 0;
  std::vector<float> pixels;  // row-major, [0, 1]
  float at(int x, int y) const { return pixels[static_cast<std::size_t>(y) * width + x]; }
};

/// Reads a PNG file as 8-bit gray (libpng converts colour and palette images).
inline GrayImage read_png_gray(const std::string& path) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&image, path.c_str())) throw std::runtime_error(path + ": " + image.message);
  image.format = PNG_FORMAT_GRAY;
  std::vector<unsigned char> bytes(PNG_IMAGE_SIZE(image));
  if (!png_image_finish_read(&image, nullptr, bytes.data(), 0, nullptr)) {
    png_image_free(&image);
    throw std::runtime_error(path + ": " + image.message);
  }
  GrayImage out;
  out.width = static_cast<int>(image.width), out.height = static_cast<int>(image.height);
  out.pixels.resize(bytes.size());
  for (std::size_t i = 0; i < bytes.size(); ++i) out.pixels[i] = static_cast<float>(bytes[i]) / 255.f;
  return out;
}

/// Separable Gaussian smoothing, edges clamped.
inline GrayImage smooth(const GrayImage& in, float sigma) {
  const int radius = static_cast<int>(std::ceil(3 * sigma));
  std::vector<float> kernel(2 * radius + 1);
  float sum = 0;
  for (int i = -radius; i <= radius; ++i) {
    const float t = static_cast<float>(i) / sigma;
    sum += kernel[i + radius] = std::exp(-0.5f * t * t);
  }
  for (float& k : kernel) k /= sum;
  GrayImage tmp = in, out = in;
  for (int y = 0; y < in.height; ++y)
    for (int x = 0; x < in.width; ++x) {
      float s = 0;
      for (int i = -radius; i <= radius; ++i) s += kernel[i + radius] * in.at(std::clamp(x + i, 0, in.width - 1), y);
      tmp.pixels[static_cast<std::size_t>(y) * in.width + x] = s;
    }
  for (int y = 0; y < in.height; ++y)
    for (int x = 0; x < in.width; ++x) {
      float s = 0;
      for (int i = -radius; i <= radius; ++i) s += kernel[i + radius] * tmp.at(x, std::clamp(y + i, 0, in.height - 1));
      out.pixels[static_cast<std::size_t>(y) * in.width + x] = s;
    }
  return out;
}

/// Every second pixel of every second row.
inline GrayImage halve(const GrayImage& in) {
  GrayImage out;
  out.width = in.width / 2, out.height = in.height / 2;
  out.pixels.resize(static_cast<std::size_t>(out.width) * out.height);
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x) out.pixels[static_cast<std::size_t>(y) * out.width + x] = in.at(2 * x, 2 * y);
  return out;
}

/// Appends the descriptors of one octave to `out`.
inline void describe_octave(const GrayImage& img, int stride, float min_gradient, std::vector<float>& out) {
  constexpr int window = 16, cells = 4, bins = 8;
  constexpr float two_pi = 6.28318530718f;
  const int w = img.width, h = img.height;
  std::vector<float> magnitude(static_cast<std::size_t>(w) * h, 0.f), orientation(magnitude.size(), 0.f);
  for (int y = 1; y + 1 < h; ++y)
    for (int x = 1; x + 1 < w; ++x) {
      const float dx = img.at(x + 1, y) - img.at(x - 1, y), dy = img.at(x, y + 1) - img.at(x, y - 1);
      const std::size_t i = static_cast<std::size_t>(y) * w + x;
      magnitude[i] = std::sqrt(dx * dx + dy * dy);
      float angle = std::atan2(dy, dx);
      if (angle < 0) angle += two_pi;
      orientation[i] = angle;
    }
  // What depends only on a pixel's place in the window: its Gaussian weight, and its position in
  // cell units (cell centres at 0..3) as the cell below and the fraction beyond it.
  struct Place {
    float weight, fx, fy;
    int x0, y0;
  };
  std::vector<Place> places(window * window);
  const float half = static_cast<float>(window) / 2.f, cell_size = static_cast<float>(window) / cells;
  for (int v = 0; v < window; ++v)
    for (int u = 0; u < window; ++u) {
      const float fu = static_cast<float>(u) + 0.5f, fv = static_cast<float>(v) + 0.5f;
      const float du = fu - half, dv = fv - half;
      const float px = fu / cell_size - 0.5f, py = fv / cell_size - 0.5f;
      const int x0 = static_cast<int>(std::floor(px)), y0 = static_cast<int>(std::floor(py));
      places[static_cast<std::size_t>(v * window + u)] = {std::exp(-(du * du + dv * dv) / (2 * half * half)),
                                                          px - static_cast<float>(x0), py - static_cast<float>(y0), x0, y0};
    }
  float histogram[cells * cells * bins];
  for (int cy = window / 2 + 1; cy + window / 2 + 1 < h; cy += stride)
    for (int cx = window / 2 + 1; cx + window / 2 + 1 < w; cx += stride) {
      std::fill(std::begin(histogram), std::end(histogram), 0.f);
      float gradient_sum = 0;
      for (int v = 0; v < window; ++v)
        for (int u = 0; u < window; ++u) {
          const int x = cx - window / 2 + u, y = cy - window / 2 + v;
          const std::size_t i = static_cast<std::size_t>(y) * w + x;
          const Place& place = places[static_cast<std::size_t>(v * window + u)];
          const float m = magnitude[i] * place.weight;
          gradient_sum += magnitude[i];
          const int x0 = place.x0, y0 = place.y0;
          const float fx = place.fx, fy = place.fy;
          const float po = orientation[i] / two_pi * static_cast<float>(bins);
          const int o0 = static_cast<int>(std::floor(po));
          const float fo = po - static_cast<float>(o0);
          for (int j = 0; j < 2; ++j) {
            const int yy = y0 + j;
            if (yy < 0 || yy >= cells) continue;
            const float wy = j ? fy : 1 - fy;
            for (int k = 0; k < 2; ++k) {
              const int xx = x0 + k;
              if (xx < 0 || xx >= cells) continue;
              const float wx = k ? fx : 1 - fx;
              for (int l = 0; l < 2; ++l) {
                const int oo = ((o0 + l) % bins + bins) % bins;
                histogram[(yy * cells + xx) * bins + oo] += m * wy * wx * (l ? fo : 1 - fo);
              }
            }
          }
        }
      if (gradient_sum / static_cast<float>(window * window) < min_gradient) continue;
      auto normalise = [&] {
        float norm = 0;
        for (float value : histogram) norm += value * value;
        norm = std::sqrt(norm);
        if (norm > 0)
          for (float& value : histogram) value /= norm;
      };
      normalise();
      for (float& value : histogram) value = std::min(value, 0.2f);
      normalise();
      for (float value : histogram) out.push_back(std::min(255.f, std::round(512.f * value)));
    }
}

/// The descriptors of one photo over `octaves` octaves, row-major (image_descriptor_dim a row).
inline std::vector<float> photo_descriptors(const std::string& path, int stride = 4, int octaves = 3,
                                            float min_gradient = 0.01f) {
  std::vector<float> out;
  GrayImage level = smooth(read_png_gray(path), 1.0f);
  for (int octave = 0; octave < octaves && level.width > 24 && level.height > 24; ++octave) {
    describe_octave(level, stride, min_gradient, out);
    level = halve(smooth(level, 1.6f));
  }
  return out;
}

/// At most `count` rows of `rows` (dim each), evenly spaced.
inline std::vector<float> evenly_spaced_rows(const std::vector<float>& rows, std::size_t dim, std::size_t count) {
  const std::size_t total = rows.size() / dim;
  if (count >= total) return rows;
  std::vector<float> out;
  out.reserve(count * dim);
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t row = i * total / count;
    out.insert(out.end(), rows.begin() + static_cast<long>(row * dim), rows.begin() + static_cast<long>((row + 1) * dim));
  }
  return out;
}

}  // namespace kdspace_bench
