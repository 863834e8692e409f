// kdspace-bench: build time and exact k-NN throughput of kdspace, FLANN (KDTreeSingleIndex) and
// nanoflann (run-time and compile-time dimension) on identical data, in one process. Repetitions are
// interleaved across libraries so a drift in machine speed hits all alike; answers are cross-checked.
//
// usage: kdspace-bench [--n N] [--dim D] [--queries Q] [--reps R] [--clustered]
//   dim 3 also runs the compile-time-dimension variants (kdspace PointTree<float, 3>, nanoflann DIM=3).
#include <flann/flann.hpp>
#include <nanoflann.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "kdspace/kdspace.hpp"

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

std::vector<float> make_points(std::size_t n, std::size_t dim, bool clustered, std::uint32_t seed) {
  std::mt19937 centre_rng(12345);  // the same blobs for base and queries
  std::uniform_real_distribution<float> uniform(0.f, 1.f);
  std::vector<float> centres(64 * dim);
  for (auto& c : centres) c = uniform(centre_rng);
  std::mt19937 rng(seed);
  std::normal_distribution<float> spread(0.f, 0.03f);
  std::vector<float> points(n * dim);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t blob = rng() % 64;
    for (std::size_t a = 0; a < dim; ++a)
      points[i * dim + a] = clustered ? centres[blob * dim + a] + spread(rng) : uniform(rng);
  }
  return points;
}

// nanoflann reads points through an adaptor.
struct RowMajorCloud {
  const float* data;
  std::size_t n, dim;
  std::size_t kdtree_get_point_count() const { return n; }
  float kdtree_get_pt(std::size_t i, std::size_t a) const { return data[i * dim + a]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }
};

/// One library under test: build() makes its index, knn() answers all queries (ids, squared-or-true
/// distances converted to true distances).
struct Contender {
  std::string name;
  std::function<void()> build;
  std::function<void(std::size_t k, std::vector<std::uint32_t>& ids, std::vector<float>& dists)> knn;
  std::function<void()> release;
  std::vector<double> build_s;
  std::vector<double> knn_s[2];
};

template <int Dim>
void add_kdspace(std::vector<Contender>& out, const std::string& name, const std::vector<float>& base,
                 const std::vector<float>& queries, std::size_t dim) {
  auto tree = std::make_shared<std::unique_ptr<kdspace::PointTree<float, Dim>>>();
  Contender c;
  c.name = name;
  c.build = [=, &base] {
    *tree = std::make_unique<kdspace::PointTree<float, Dim>>(base.data(), base.size() / dim, dim);
  };
  c.knn = [=, &queries](std::size_t k, std::vector<std::uint32_t>& ids, std::vector<float>& dists) {
    const std::size_t nq = queries.size() / dim;
    const auto lists = (*tree)->knn_batch(queries.data(), nq, k, {}, 1);
    for (std::size_t i = 0; i < nq * k; ++i) ids[i] = lists.neighbors[i].index, dists[i] = lists.neighbors[i].distance;
  };
  c.release = [=] { tree->reset(); };
  out.push_back(std::move(c));
}

template <int Dim>
void add_nanoflann(std::vector<Contender>& out, const std::string& name, const std::vector<float>& base,
                   const std::vector<float>& queries, std::size_t dim) {
  using Index = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, RowMajorCloud>,
                                                    RowMajorCloud, Dim, std::uint32_t>;
  auto cloud = std::make_shared<RowMajorCloud>(RowMajorCloud{base.data(), base.size() / dim, dim});
  auto index = std::make_shared<std::unique_ptr<Index>>();
  Contender c;
  c.name = name;
  c.build = [=] {
    *index = std::make_unique<Index>(static_cast<int>(dim), *cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  };
  c.knn = [=, &queries](std::size_t k, std::vector<std::uint32_t>& ids, std::vector<float>& dists) {
    const std::size_t nq = queries.size() / dim;
    for (std::size_t q = 0; q < nq; ++q) {
      (*index)->knnSearch(queries.data() + q * dim, k, ids.data() + q * k, dists.data() + q * k);
      for (std::size_t j = 0; j < k; ++j) dists[q * k + j] = std::sqrt(dists[q * k + j]);  // nanoflann: squared
    }
  };
  c.release = [=] { index->reset(); };
  out.push_back(std::move(c));
}

void add_flann(std::vector<Contender>& out, const std::vector<float>& base, const std::vector<float>& queries,
               std::size_t dim) {
  using Index = flann::Index<flann::L2_Simple<float>>;
  auto index = std::make_shared<std::unique_ptr<Index>>();
  Contender c;
  c.name = "FLANN KDTreeSingleIndex";
  c.build = [=, &base] {
    flann::Matrix<float> data(const_cast<float*>(base.data()), base.size() / dim, dim);
    *index = std::make_unique<Index>(data, flann::KDTreeSingleIndexParams(10));
    (*index)->buildIndex();
  };
  c.knn = [=, &queries](std::size_t k, std::vector<std::uint32_t>& ids, std::vector<float>& dists) {
    const std::size_t nq = queries.size() / dim;
    flann::Matrix<float> q(const_cast<float*>(queries.data()), nq, dim);
    std::vector<std::size_t> flann_ids(nq * k);
    flann::Matrix<std::size_t> idm(flann_ids.data(), nq, k);
    flann::Matrix<float> dm(dists.data(), nq, k);
    flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED, 0.0f, true);
    params.cores = 1;
    (*index)->knnSearch(q, idm, dm, k, params);
    for (std::size_t i = 0; i < nq * k; ++i) {
      ids[i] = static_cast<std::uint32_t>(flann_ids[i]);
      dists[i] = std::sqrt(dists[i]);  // FLANN's L2 returns squared distances
    }
  };
  c.release = [=] { index->reset(); };
  out.push_back(std::move(c));
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  std::size_t n = 1000000, dim = 3, nq = 100000, reps = 3;
  bool clustered = false;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&] { return i + 1 < argc ? std::strtoull(argv[++i], nullptr, 10) : 0ull; };
    if (arg == "--n") n = value();
    else if (arg == "--dim") dim = value();
    else if (arg == "--queries") nq = value();
    else if (arg == "--reps") reps = value();
    else if (arg == "--clustered") clustered = true;
    else {
      std::fprintf(stderr, "usage: kdspace-bench [--n N] [--dim D] [--queries Q] [--reps R] [--clustered]\n");
      return 2;
    }
  }
  if (n == 0 || dim == 0 || nq == 0 || reps == 0) {
    std::fprintf(stderr, "kdspace-bench: n, dim, queries and reps must be positive\n");
    return 2;
  }
  const auto base = make_points(n, dim, clustered, 1);
  const auto queries = make_points(nq, dim, clustered, 2);

  std::vector<Contender> contenders;
  add_kdspace<kdspace::Dynamic>(contenders, "kdspace (run-time dim)", base, queries, dim);
  if (dim == 3) add_kdspace<3>(contenders, "kdspace (compile-time dim)", base, queries, dim);
  add_flann(contenders, base, queries, dim);
  add_nanoflann<-1>(contenders, "nanoflann (run-time dim)", base, queries, dim);
  if (dim == 3) add_nanoflann<3>(contenders, "nanoflann (compile-time dim)", base, queries, dim);

  const std::size_t ks[2] = {1, 10};
  std::vector<std::uint32_t> ids(nq * 10), ref_ids(nq * 10);
  std::vector<float> dists(nq * 10), ref_dists(nq * 10);
  std::size_t disagreements = 0;
  for (std::size_t rep = 0; rep < reps; ++rep) {
    for (auto& c : contenders) {  // interleaved: every library once per repetition
      auto start = Clock::now();
      c.build();
      c.build_s.push_back(seconds_since(start));
      for (int ki = 0; ki < 2; ++ki) {
        start = Clock::now();
        c.knn(ks[ki], ids, dists);
        c.knn_s[ki].push_back(seconds_since(start));
        if (rep == 0 && &c == &contenders.front()) {
          if (ki == 1) ref_ids = ids, ref_dists = dists;
        } else if (rep == 0 && ki == 1) {
          for (std::size_t i = 0; i < nq * 10; ++i)
            if (std::abs(dists[i] - ref_dists[i]) > 1e-5f * std::max(1.f, ref_dists[i])) ++disagreements;
        }
      }
      c.release();
    }
  }

  const auto& ref = contenders.front();
  std::printf("\n%zu points, %zu-D %s, %zu queries, median of %zu interleaved runs, 1 thread\n\n", n, dim,
              clustered ? "clustered" : "uniform", nq, reps);
  std::printf("| library | build s | 1-NN q/s | 10-NN q/s | its time ÷ kdspace run-time-dim time (build, 1-NN, 10-NN) |\n");
  std::printf("|---|---:|---:|---:|---|\n");
  for (const auto& c : contenders) {
    const double b = median(c.build_s), k1 = median(c.knn_s[0]), k10 = median(c.knn_s[1]);
    std::printf("| %s | %.3f | %.0f | %.0f | %.2fx, %.2fx, %.2fx |\n", c.name.c_str(), b, static_cast<double>(nq) / k1,
                static_cast<double>(nq) / k10, b / median(ref.build_s), k1 / median(ref.knn_s[0]),
                k10 / median(ref.knn_s[1]));
  }
  for (const auto& c : contenders)
    std::printf("{\"library\":\"%s\",\"n\":%zu,\"dim\":%zu,\"clustered\":%s,\"build_s\":%.6f,\"knn1_qps\":%.1f,\"knn10_qps\":%.1f}\n",
                c.name.c_str(), n, dim, clustered ? "true" : "false", median(c.build_s),
                static_cast<double>(nq) / median(c.knn_s[0]), static_cast<double>(nq) / median(c.knn_s[1]));
  std::printf("\n10-NN distances that disagree with kdspace beyond 1e-5 relative: %zu\n", disagreements);
  return disagreements == 0 ? 0 : 1;
}
