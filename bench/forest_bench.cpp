// kdspace-forest-bench: approximate 10-NN of kdspace's PointForest against FLANN's randomized
// kd-forest (KDTreeIndex, 4 and 8 trees, flann::L2<float>), on identical data, in one process.
//
// For each data set both libraries build their forests, then answer the same queries on one thread
// with budgets (`checks`) from 16 to 4096; recall@1 and recall@10 are measured against exact answers
// (kdspace's blocked scan, exact by construction), counting a returned point as found when its true
// distance is no larger than the true k-th (so ties count). Recall@1 is read from the first entry of
// the 10-NN answer. Repetitions are interleaved (for each budget: FLANN then kdspace, each
// configuration), the median time is kept. Then, for recall@10 targets 0.8, 0.9, 0.95 and 0.99, the
// fastest configuration of each library that reaches the target, and the ratio. Last, kdspace's own
// tuning for recall@10 = 0.9 on 400 other queries drawn like the bench's: the setting it chose, the
// time it took, and the recall and speed of that setting on the bench's queries (which the tuning
// never saw).
//
// Data sets (all generated with fixed seeds; base and queries drawn independently):
//   structured32d/64d/128d  100k points in 64 clusters; inside a cluster the points vary along 12
//                           random directions with decaying spreads, plus a little noise in every
//                           direction (descriptor-like: high ambient, low intrinsic dimension)
//   blobs128d               100k points in 64 isotropic Gaussian blobs (intrinsic dimension 128:
//                           the hard case for every kd-tree method)
//   mfcc                    audio descriptors computed here: 13 MFCCs with deltas and delta-deltas
//                           (39-D) of 25 ms frames of synthetic audio (notes of harmonic tones with
//                           vibrato and envelopes, over noise), see audio_features.hpp
//   images                  image descriptors computed here: dense SIFT-like 128-D descriptors of 12
//                           photographs (base) and of the other view of one of them (queries), see
//                           image_features.hpp; needs the photos in --images DIR (run_all.sh
//                           unpacks them), else this data set is skipped
//   --fvecs BASE QUERIES    any file pair (fvecs, bvecs, npy, csv: read by kdspace::io)
//
// usage: kdspace-forest-bench [--dataset NAME]... [--fvecs BASE QUERIES]... [--images DIR] [--quick]
//                             [--reps R] [--leaf L] [--projected M] [--no-pca]
// Output: per data set a markdown table of the curves and one of the targets, then JSON lines
// ({"bench":"forest",...}). Progress on stderr.
#include <flann/flann.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "audio_features.hpp"
#include "image_features.hpp"
#include "kdspace/io/vectors.hpp"
#include "kdspace/metric.hpp"
#include "kdspace/points/point_forest.hpp"

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

constexpr std::size_t k = 10;
// Budgets from 16 to 4096 in steps of about sqrt(2), the same for both libraries: a coarser grid
// would let either library's best setting fall far above the target and blur the ratio.
const std::size_t kChecks[] = {16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512, 768, 1024, 1536, 2048, 3072, 4096};
const double kTargets[] = {0.8, 0.9, 0.95, 0.99};

struct Data {
  std::string name, description;
  std::size_t n = 0, nq = 0, dim = 0;
  std::vector<float> base, queries;
  std::vector<float> tuning_queries;  // drawn like the queries, apart from them: for tune()
};

// Points in 64 clusters. Cluster c has a centre in [0, 1)^dim and `latent` random directions; a point
// is centre + sum_j z_j * scale_j * direction_j + noise, z_j standard normal, scale_j decaying
// geometrically from 0.12. `latent` = 0 gives isotropic blobs of standard deviation 0.03.
std::vector<float> make_clusters(std::size_t n, std::size_t dim, std::size_t latent, std::uint32_t seed) {
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

/// The image descriptor data set from the photos in `folder`: every base descriptor when there are
/// at most n, else n evenly spaced; queries and tuning queries from the even and odd descriptors of
/// the query photo.
Data photos(const std::string& folder, std::size_t n, std::size_t nq) {
  using namespace kdspace_bench;
  Data d;
  d.name = "images";
  d.dim = image_descriptor_dim;
  std::vector<float> all;
  for (const std::string& photo : base_photos()) {
    const std::vector<float> one = photo_descriptors(folder + "/" + photo + ".png");
    all.insert(all.end(), one.begin(), one.end());
  }
  const std::size_t available = all.size() / d.dim;
  d.base = evenly_spaced_rows(all, d.dim, n);
  d.n = d.base.size() / d.dim;
  const std::vector<float> view = photo_descriptors(folder + "/" + std::string(query_photo()) + ".png");
  std::vector<float> even, odd;
  for (std::size_t r = 0; r < view.size() / d.dim; ++r) {
    std::vector<float>& half = r % 2 ? odd : even;
    half.insert(half.end(), view.begin() + static_cast<long>(r * d.dim), view.begin() + static_cast<long>((r + 1) * d.dim));
  }
  d.queries = evenly_spaced_rows(even, d.dim, nq);
  d.nq = d.queries.size() / d.dim;
  d.tuning_queries = evenly_spaced_rows(odd, d.dim, 400);
  d.description = "128-D dense SIFT-like descriptors of 12 photographs (" + std::to_string(d.n) + " of " +
                  std::to_string(available) + "), queries from the other view of one of them; image_features.hpp";
  return d;
}

Data synthetic(const std::string& name, std::size_t n, std::size_t nq, std::size_t dim, std::size_t latent) {
  Data d;
  d.name = name;
  d.n = n, d.nq = nq, d.dim = dim;
  d.description = latent ? std::to_string(dim) + "-D, 64 clusters of intrinsic dimension " + std::to_string(latent)
                         : std::to_string(dim) + "-D, 64 isotropic Gaussian blobs";
  d.base = make_clusters(n, dim, latent, 1);
  d.queries = make_clusters(nq, dim, latent, 2);
  d.tuning_queries = make_clusters(400, dim, latent, 3);
  return d;
}

// ---- measurements -----------------------------------------------------------------------------------

struct Point {  // one configuration at one budget
  std::string library;
  std::size_t trees = 0, checks = 0;
  std::vector<double> seconds;  // one per repetition
  double recall1 = 0, recall10 = 0;
  double qps(std::size_t nq) const {
    std::vector<double> s = seconds;
    std::sort(s.begin(), s.end());
    return static_cast<double>(nq) / s[s.size() / 2];
  }
};

/// Recall@1 and @10 of answers given as ids (row-major, k a row), using true distances.
struct Recall {
  double at1, at10;
};
Recall recall_of(const Data& d, const std::vector<std::uint32_t>& ids, const kdspace::NeighborLists<float>& exact) {
  double hits1 = 0, hits10 = 0;
  for (std::size_t q = 0; q < d.nq; ++q) {
    const float* query = d.queries.data() + q * d.dim;
    const float first = exact.row(q)[0].distance, kth = exact.row(q)[k - 1].distance;
    for (std::size_t i = 0; i < k; ++i) {
      const float dist = std::sqrt(kdspace::internal_distance<kdspace::L2>(query, d.base.data() + std::size_t{ids[q * k + i]} * d.dim, d.dim));
      if (dist <= kth) hits10 += 1;
      if (i == 0 && dist <= first) hits1 += 1;
    }
  }
  return {hits1 / static_cast<double>(d.nq), hits10 / static_cast<double>(d.nq * k)};
}

class FlannForest {
 public:
  FlannForest(const Data& d, std::size_t trees) : d_(d) {
    flann::Matrix<float> data(const_cast<float*>(d.base.data()), d.n, d.dim);
    const auto start = Clock::now();
    index_ = std::make_unique<Index>(data, flann::KDTreeIndexParams(static_cast<int>(trees)));
    index_->buildIndex();
    build_s = seconds_since(start);
  }
  double search(std::size_t checks, std::vector<std::uint32_t>& ids) {
    flann::Matrix<float> q(const_cast<float*>(d_.queries.data()), d_.nq, d_.dim);
    std::vector<std::size_t> found(d_.nq * k);
    std::vector<float> dists(d_.nq * k);
    flann::Matrix<std::size_t> id_matrix(found.data(), d_.nq, k);
    flann::Matrix<float> dist_matrix(dists.data(), d_.nq, k);
    flann::SearchParams params(static_cast<int>(checks), 0.0f, true);
    params.cores = 1;
    const auto start = Clock::now();
    index_->knnSearch(q, id_matrix, dist_matrix, k, params);
    const double s = seconds_since(start);
    ids.assign(found.begin(), found.end());
    return s;
  }
  double build_s = 0;

 private:
  using Index = flann::Index<flann::L2<float>>;
  const Data& d_;
  std::unique_ptr<Index> index_;
};

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

kdspace::ForestParams g_params;  // --leaf, --projected, --no-pca change it

void run(const Data& d, std::size_t reps) {
  std::fprintf(stderr, "%s: %zu points, %zu queries, %zu-D\n", d.name.c_str(), d.n, d.nq, d.dim);
  kdspace::ForestParams params = g_params;
  params.trees = 8;
  auto start = Clock::now();
  const kdspace::PointForest<float> forest(d.base.data(), d.n, d.dim, params);
  const double kdspace_build = seconds_since(start);
  start = Clock::now();
  const auto exact = forest.knn_exact_batch(d.queries.data(), d.nq, k, 0);
  const double exact_s = seconds_since(start);
  std::fprintf(stderr, "  kdspace 8 trees built in %.3f s; exact answers in %.2f s\n", kdspace_build, exact_s);
  // The 4-tree kdspace forest is the first 4 trees of the 8 (the same draws); its build is timed alone.
  params.trees = 4;
  start = Clock::now();
  { const kdspace::PointForest<float> four(d.base.data(), d.n, d.dim, params); }
  const double kdspace_build4 = seconds_since(start);

  FlannForest flann4(d, 4), flann8(d, 8);
  std::fprintf(stderr, "  FLANN built in %.3f s (4 trees), %.3f s (8 trees)\n", flann4.build_s, flann8.build_s);

  std::vector<Point> points;
  for (std::size_t checks : kChecks) {
    for (std::size_t t : {4, 8}) points.push_back({"flann", t, checks, {}, 0, 0});
    for (std::size_t t : {1, 2, 4, 8}) points.push_back({"kdspace", t, checks, {}, 0, 0});
  }
  std::vector<std::uint32_t> ids;
  for (std::size_t rep = 0; rep < reps; ++rep) {
    std::fprintf(stderr, "  repetition %zu of %zu\n", rep + 1, reps);
    for (Point& p : points) {
      double s;
      if (p.library == "flann") {
        s = (p.trees == 4 ? flann4 : flann8).search(p.checks, ids);
      } else {
        start = Clock::now();
        const auto found = forest.knn_batch(d.queries.data(), d.nq, k, {p.checks, p.trees}, 1);
        s = seconds_since(start);
        ids.resize(d.nq * k);
        for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = found.neighbors[i].index;
      }
      p.seconds.push_back(s);
      if (rep == 0) {
        const Recall r = recall_of(d, ids, exact);
        p.recall1 = r.at1, p.recall10 = r.at10;
      }
    }
  }

  // kdspace's own tuning for recall@10 = 0.9 on other queries of the same kind, then that setting on
  // the bench's queries.
  const kdspace::ForestTuning tuned = forest.tune(0.9, k, d.tuning_queries.data(), d.tuning_queries.size() / d.dim);
  start = Clock::now();
  const auto tuned_found = forest.knn_batch(d.queries.data(), d.nq, k, {tuned.checks, tuned.trees}, 1);
  const double tuned_s = seconds_since(start);
  const double tuned_recall = kdspace::recall_at_k(tuned_found, exact);

  std::printf("\n### %s (%s; %zu points, %zu queries)\n\n", d.name.c_str(), d.description.c_str(), d.n, d.nq);
  std::printf("Build: kdspace %.3f s (4 trees), %.3f s (8 trees), splitting %zu %s, points kept as %s; FLANN "
              "%.3f s (4 trees), %.3f s (8 trees).\n\n",
              kdspace_build4, kdspace_build, forest.projected_dims(),
              forest.params().pca ? "principal directions" : "original axes", forest.compact() ? "bytes" : "floats",
              flann4.build_s, flann8.build_s);
  std::printf("| library | trees | checks | recall@1 | recall@10 | q/s |\n|---|---:|---:|---:|---:|---:|\n");
  for (const Point& p : points)
    std::printf("| %s | %zu | %zu | %.3f | %.3f | %.0f |\n", p.library.c_str(), p.trees, p.checks, p.recall1, p.recall10,
                p.qps(d.nq));
  std::printf("\n| recall@10 at least | kdspace q/s (trees, checks) | FLANN q/s (trees, checks) | kdspace ÷ FLANN |\n"
              "|---:|---:|---:|---:|\n");
  for (double target : kTargets) {
    const Point* best[2] = {nullptr, nullptr};
    for (const Point& p : points) {
      if (p.recall10 < target) continue;
      const Point*& slot = best[p.library == "kdspace" ? 0 : 1];
      if (!slot || p.qps(d.nq) > slot->qps(d.nq)) slot = &p;
    }
    auto cell = [&](const Point* p) {
      return p ? fmt("%.0f", p->qps(d.nq)) + " (" + std::to_string(p->trees) + ", " + std::to_string(p->checks) + ")"
               : std::string("not reached");
    };
    const std::string ratio = best[0] && best[1] ? fmt("%.2f", best[0]->qps(d.nq) / best[1]->qps(d.nq)) : "-";
    std::printf("| %.2f | %s | %s | %s |\n", target, cell(best[0]).c_str(), cell(best[1]).c_str(), ratio.c_str());
    std::printf("{\"bench\":\"forest\",\"dataset\":\"%s\",\"dim\":%zu,\"n\":%zu,\"target_recall10\":%.2f,"
                "\"kdspace_qps\":%.1f,\"flann_qps\":%.1f,\"ratio\":%s}\n",
                d.name.c_str(), d.dim, d.n, target, best[0] ? best[0]->qps(d.nq) : 0.0, best[1] ? best[1]->qps(d.nq) : 0.0,
                best[0] && best[1] ? ratio.c_str() : "null");
  }
  std::printf("\nkdspace tune(recall@10 = 0.9): %zu trees, %zu checks, chosen in %.2f s (%zu settings tried; recall "
              "%.3f on its sample, %.3f held out); on the bench's queries: recall@10 %.3f at %.0f q/s.\n\n",
              tuned.trees, tuned.checks, tuned.seconds, tuned.settings_tried, tuned.tuning_recall,
              tuned.validation_recall, tuned_recall, static_cast<double>(d.nq) / tuned_s);
  for (const Point& p : points)
    std::printf("{\"bench\":\"forest\",\"dataset\":\"%s\",\"dim\":%zu,\"n\":%zu,\"queries\":%zu,\"library\":\"%s\","
                "\"trees\":%zu,\"checks\":%zu,\"recall1\":%.4f,\"recall10\":%.4f,\"qps\":%.1f,\"reps\":%zu}\n",
                d.name.c_str(), d.dim, d.n, d.nq, p.library.c_str(), p.trees, p.checks, p.recall1, p.recall10,
                p.qps(d.nq), reps);
  std::printf("{\"bench\":\"forest\",\"dataset\":\"%s\",\"dim\":%zu,\"n\":%zu,\"op\":\"build\",\"kdspace_4_s\":%.4f,"
              "\"kdspace_8_s\":%.4f,\"flann_4_s\":%.4f,\"flann_8_s\":%.4f}\n",
              d.name.c_str(), d.dim, d.n, kdspace_build4, kdspace_build, flann4.build_s, flann8.build_s);
  std::printf("{\"bench\":\"forest\",\"dataset\":\"%s\",\"dim\":%zu,\"n\":%zu,\"op\":\"tune\",\"target_recall10\":0.9,"
              "\"trees\":%zu,\"checks\":%zu,\"tune_s\":%.3f,\"tuning_recall\":%.4f,\"validation_recall\":%.4f,"
              "\"bench_recall\":%.4f,\"qps\":%.1f}\n",
              d.name.c_str(), d.dim, d.n, tuned.trees, tuned.checks, tuned.seconds, tuned.tuning_recall,
              tuned.validation_recall, tuned_recall, static_cast<double>(d.nq) / tuned_s);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> names;
  std::vector<std::pair<std::string, std::string>> files;
  bool quick = false;
  std::string images;
  std::size_t reps = 3;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--quick") quick = true;
    else if (a == "--dataset" && i + 1 < argc) names.push_back(argv[++i]);
    else if (a == "--reps" && i + 1 < argc) reps = std::max(1, std::atoi(argv[++i]));
    else if (a == "--leaf" && i + 1 < argc) g_params.leaf_size = static_cast<std::size_t>(std::atoi(argv[++i]));
    else if (a == "--projected" && i + 1 < argc) g_params.projected_dims = static_cast<std::size_t>(std::atoi(argv[++i]));
    else if (a == "--no-pca") g_params.pca = false;
    else if (a == "--images" && i + 1 < argc) images = argv[++i];
    else if (a == "--fvecs" && i + 2 < argc) files.emplace_back(argv[i + 1], argv[i + 2]), i += 2;
    else {
      std::fprintf(stderr, "usage: kdspace-forest-bench [--dataset structured32d|structured64d|structured128d|blobs128d|mfcc|images]..."
                           " [--fvecs BASE QUERIES]... [--images DIR] [--quick] [--reps R] [--leaf L] [--projected M] [--no-pca]\n");
      return 2;
    }
  }
  if (quick) reps = 1;
  if (names.empty() && files.empty()) {
    names = {"structured32d", "mfcc", "structured64d", "structured128d", "blobs128d"};
    if (!images.empty()) names.push_back("images");
    else std::fprintf(stderr, "kdspace-forest-bench: no --images DIR: the image descriptor data set is skipped\n");
  }
  const std::size_t n = quick ? 20000 : 100000, nq = quick ? 200 : 1000;
  std::printf("# kdspace-forest-bench: approximate 10-NN, kdspace PointForest vs FLANN KDTreeIndex, 1 thread, median of %zu\n",
              reps);
  try {
    for (const std::string& name : names) {
      if (name == "structured32d") run(synthetic(name, n, nq, 32, 12), reps);
      else if (name == "structured64d") run(synthetic(name, n, nq, 64, 12), reps);
      else if (name == "structured128d") run(synthetic(name, n, nq, 128, 12), reps);
      else if (name == "blobs128d") run(synthetic(name, n, nq, 128, 0), reps);
      else if (name == "images") {
        if (images.empty()) throw std::runtime_error("the images data set needs --images DIR");
        run(photos(images, n, nq), reps);
      }
      else if (name == "mfcc") {
        Data d;
        d.name = "mfcc";
        d.description = "39-D MFCC frames of synthetic audio, computed by bench/audio_features.hpp";
        d.base = kdspace_bench::mfcc_frames(n, 1);
        d.queries = kdspace_bench::mfcc_frames(nq, 2);
        d.tuning_queries = kdspace_bench::mfcc_frames(400, 3);
        d.dim = kdspace_bench::mfcc_dim;
        d.n = n, d.nq = nq;
        run(d, reps);
      } else {
        std::fprintf(stderr, "kdspace-forest-bench: unknown data set %s\n", name.c_str());
        return 2;
      }
    }
    for (const auto& [base_path, query_path] : files) {
      Data d;
      const auto base = kdspace::io::read_points<float>(base_path);
      const auto queries = kdspace::io::read_points<float>(query_path);
      d.name = base_path;
      d.description = "file";
      d.base = base.data, d.queries = queries.data;
      // Tuning draws from the bench's own queries here (no other queries of that kind at hand).
      d.tuning_queries = queries.data;
      d.n = base.rows, d.nq = queries.rows, d.dim = base.cols;
      if (queries.cols != d.dim) {
        std::fprintf(stderr, "kdspace-forest-bench: %s and %s differ in dimension\n", base_path.c_str(), query_path.c_str());
        return 1;
      }
      run(d, reps);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "kdspace-forest-bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
