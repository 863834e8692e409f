// The data sets of kdspace-ann-bench: real descriptors computed here from recordings and photographs
// that Debian packages ship, and synthetic clustered points. Each has base points, queries drawn
// apart from them, and as many tuning queries again (drawn like the queries, apart from both), for
// the index's own tuning.
//
//   speech      39-D MFCC (13 + deltas + delta-deltas) of a US English voice recorded for telephone
//               prompts (asterisk-core-sounds-en-wav, 568 files, 8 kHz): every 8th file gives the
//               queries, the others the base
//   music       20-D MFCC of the soundtrack of a game (asc-music, 3 pieces, 44.1 kHz MP3): blocks of
//               2 s, every 10th block gives the queries, the others the base
//   images      128-D SIFT-like descriptors (bytes) of 12 photographs (python3-skimage), queries from
//               the other view of one of them (image_features.hpp)
//   clusteredD  D-dimensional points in 64 clusters, each varying along 12 random directions with
//               decaying spreads plus a little noise in every direction (high ambient, low intrinsic
//               dimension, like descriptors); D = 8, 16, 32, 64, 128, 960
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "audio_files.hpp"
#include "image_features.hpp"

namespace kdspace_bench {

struct AnnData {
  std::string name, description;
  std::size_t dim = 0;
  std::vector<float> base, queries, tuning_queries;
  std::size_t n() const { return base.size() / dim; }
  std::size_t nq() const { return queries.size() / dim; }
};

/// Points in 64 clusters. Cluster c has a centre in [0, 1)^dim and `latent` random directions; a point
/// is centre + sum_j z_j * scale_j * direction_j + noise, z_j standard normal, scale_j decaying
/// geometrically from 0.12. `latent` = 0 gives isotropic blobs of standard deviation 0.03.
inline std::vector<float> make_clusters(std::size_t n, std::size_t dim, std::size_t latent, std::uint32_t seed) {
  const std::size_t clusters = 64;
  std::mt19937 shape_rng(2024);
  std::uniform_real_distribution<float> unit(0.f, 1.f);
  std::normal_distribution<float> normal(0.f, 1.f);
  std::vector<float> centres(clusters * dim), directions(clusters * latent * dim);
  for (auto& c : centres) c = unit(shape_rng);
  for (auto& d : directions) d = normal(shape_rng) / std::sqrt(static_cast<float>(dim));
  std::mt19937 rng(seed);
  std::vector<float> points(n * dim);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t c = rng() % clusters;
    float* p = points.data() + i * dim;
    for (std::size_t a = 0; a < dim; ++a) p[a] = centres[c * dim + a] + (latent == 0 ? 0.03f : 0.004f) * normal(rng);
    float scale = 0.12f;
    for (std::size_t j = 0; j < latent; ++j, scale *= 0.8f) {
      const float z = scale * normal(rng);
      const float* direction = directions.data() + (c * latent + j) * dim;
      for (std::size_t a = 0; a < dim; ++a) p[a] += z * direction[a];
    }
  }
  return points;
}

inline AnnData clustered(std::size_t n, std::size_t nq, std::size_t dim) {
  AnnData d;
  d.name = "clustered" + std::to_string(dim) + "d";
  d.dim = dim;
  d.description = std::to_string(dim) + "-D synthetic, 64 clusters of intrinsic dimension 12";
  d.base = make_clusters(n, dim, 12, 1);
  d.queries = make_clusters(nq, dim, 12, 2);
  d.tuning_queries = make_clusters(nq, dim, 12, 3);
  return d;
}

/// Queries and tuning queries from `pool` (rows of `dim`): nq evenly spaced rows of its even rows,
/// and nq of its odd rows.
inline void split_queries(const std::vector<float>& pool, std::size_t nq, AnnData& d) {
  std::vector<float> even, odd;
  for (std::size_t r = 0; r < pool.size() / d.dim; ++r) {
    std::vector<float>& half = r % 2 ? odd : even;
    half.insert(half.end(), pool.begin() + static_cast<long>(r * d.dim), pool.begin() + static_cast<long>((r + 1) * d.dim));
  }
  d.queries = evenly_spaced_rows(even, d.dim, nq);
  d.tuning_queries = evenly_spaced_rows(odd, d.dim, nq);
}

inline AnnData photos(const std::string& folder, std::size_t n, std::size_t nq) {
  AnnData d;
  d.name = "images";
  d.dim = image_descriptor_dim;
  std::vector<float> all;
  for (const std::string& photo : base_photos()) {
    const std::vector<float> one = photo_descriptors(folder + "/" + photo + ".png");
    all.insert(all.end(), one.begin(), one.end());
  }
  d.base = evenly_spaced_rows(all, d.dim, n);
  split_queries(photo_descriptors(folder + "/" + std::string(query_photo()) + ".png"), nq, d);
  d.description = "128-D SIFT-like descriptors (bytes) of 12 photographs (" + std::to_string(d.n()) + " of " +
                  std::to_string(all.size() / d.dim) + "), queries from the other view of one of them";
  return d;
}

inline AnnData speech(const std::string& folder, std::size_t n, std::size_t nq) {
  const std::vector<std::string> files = files_under(folder, ".wav");
  if (files.empty()) throw std::runtime_error("no .wav files under " + folder);
  std::vector<std::string> base_files, query_files;
  for (std::size_t i = 0; i < files.size(); ++i) (i % 8 == 7 ? query_files : base_files).push_back(files[i]);
  AnnData d;
  d.name = "speech";
  const MfccShape shape{13, true};
  d.dim = shape.dim();
  const std::vector<float> all = mfcc_of_files(base_files, shape);
  d.base = evenly_spaced_rows(all, d.dim, n);
  split_queries(mfcc_of_files(query_files, shape), nq, d);
  d.description = "39-D MFCC of recorded speech (" + std::to_string(d.n()) + " of " + std::to_string(all.size() / d.dim) +
                  " frames of " + std::to_string(base_files.size()) + " prompts), queries from " +
                  std::to_string(query_files.size()) + " other prompts";
  return d;
}

inline AnnData music(const std::string& folder, std::size_t n, std::size_t nq) {
  std::vector<std::string> files = files_under(folder, ".mp3");
  for (const std::string& f : files_under(folder, ".ogg")) files.push_back(f);
  if (files.empty()) throw std::runtime_error("no .mp3 or .ogg files under " + folder);
  AnnData d;
  d.name = "music";
  const MfccShape shape{20, false};
  d.dim = shape.dim();
  const std::vector<float> all = mfcc_of_files(files, shape);
  constexpr std::size_t block = 200;  // frames: 2 s
  std::vector<float> base, pool;
  for (std::size_t r = 0; r < all.size() / d.dim; ++r) {
    std::vector<float>& to = (r / block) % 10 == 9 ? pool : base;
    to.insert(to.end(), all.begin() + static_cast<long>(r * d.dim), all.begin() + static_cast<long>((r + 1) * d.dim));
  }
  d.base = evenly_spaced_rows(base, d.dim, n);
  split_queries(pool, nq, d);
  d.description = "20-D MFCC of recorded music (" + std::to_string(d.n()) + " of " + std::to_string(all.size() / d.dim) +
                  " frames of " + std::to_string(files.size()) + " pieces), queries from other 2 s blocks of them";
  return d;
}

}  // namespace kdspace_bench
