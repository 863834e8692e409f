// kdspace-scan-bench: exact batched k-NN in high dimension, kdspace's blocked scan against FAISS's
// IndexFlatL2 (|x|^2 + |q|^2 - 2 x.q with the dot products from BLAS sgemm), both on one thread, in one
// process, on the same data.
//
// kdspace runs detail::blocked_scan_knn_l2, the one call PointTree::knn_batch (BatchMethod::scan)
// and PointForest's exact batch make on one thread, on the rows in the caller's order.
//
// Sets: the 128-D SIFT-like descriptors of photographs (--images DIR; ann_datasets.hpp), once as
// float rows and once as byte rows (PointForest's compact storage), and synthetic clustered 128-D points
// (float, not integers: the estimated path with its rounding bound and re-check).
//
// Repetitions are interleaved (kdspace, FAISS, kdspace, FAISS, ...); the median is reported. kdspace's
// answers are checked bit for bit against brute_force_knn on a sample of queries (exit status 1 on
// any difference); FAISS's squared distances are compared with kdspace's within 1e-5 (relative;
// absolute below 1) and its disagreements reported (its flat index is not exact by design). A last,
// separate run of the scan with its profile on gives the share of time in each phase: the checks of
// the data (small integers? overflow?), packing the point blocks, the product
// with the bound test fused in (and the candidates kept), and the exact re-check with the ranking.
//
// usage: kdspace-scan-bench [--images DIR] [--n N] [--queries Q] [--k K] [--reps R] [--clock wall|cpu]
//                           [--kernel avx512|avx2|portable]
//   --images DIR   the photographs (bench/run_all.sh fetches them); without it only synthetic data
//   --n N          base points of the clustered set (default 196000, about the images' count)
//   --queries Q    queries per set (default 2000)
//   --k K          neighbours (default 10)
//   --reps R       interleaved repetitions (default 5)
//   --clock cpu    the process's CPU time instead of wall time (a busy machine inflates wall time)
//   --kernel K     the widest product kernel kdspace may use (default avx512: the widest the processor
//                  has; avx2 or portable to see what a processor without AVX-512 or AVX2 gets)
#include <dlfcn.h>
#include <faiss/IndexFlat.h>
#include <omp.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "ann_datasets.hpp"
#include "bench_args.hpp"
#include "kdspace/points/brute_force.hpp"
#include "kdspace/points/detail/blocked_scan.hpp"

namespace {

bool g_cpu_clock = false;
kdspace::detail::ScanKernel g_widest = kdspace::detail::ScanKernel::avx512;

double now_seconds() {
  if (g_cpu_clock) {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  }
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

/// One thread for FAISS: its OpenMP loops and OpenBLAS's own threads (Debian's libopenblas0-pthread
/// starts one per core unless told; looked up at run time, whichever BLAS libblas.so.3 is).
std::string one_thread() {
  omp_set_num_threads(1);
  using SetThreads = void (*)(int);
  using GetInt = int (*)();
  using GetConfig = char* (*)();
  const auto set = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
  const auto get = reinterpret_cast<GetInt>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
  const auto config = reinterpret_cast<GetConfig>(dlsym(RTLD_DEFAULT, "openblas_get_config"));
  if (!set || !get || !config) return "a BLAS other than OpenBLAS (its threads not set)";
  set(1);
  return std::string("OpenBLAS ") + config() + ", " + std::to_string(get()) + " thread";
}

const char* kernel_name() {
  switch (g_widest) {
    case kdspace::detail::ScanKernel::avx512:
      return "AVX-512";
    case kdspace::detail::ScanKernel::avx2:
      return "AVX2";
    case kdspace::detail::ScanKernel::portable:
      break;
  }
  return "portable";
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

struct Set {
  std::string name, description;
  std::size_t dim = 0, n = 0, nq = 0;
  std::vector<float> base, queries;
  bool bytes = false;  // kdspace scans the base as byte rows
};

/// The scan's input as PointTree and PointForest give it: rows in the caller's order here.
struct ScanInput {
  std::vector<std::uint32_t> order;
  std::vector<float> centre;
  std::vector<std::uint8_t> bytes;
};

ScanInput scan_input(const Set& s) {
  ScanInput in;
  in.order.resize(s.n);
  for (std::size_t i = 0; i < s.n; ++i) in.order[i] = static_cast<std::uint32_t>(i);
  std::vector<float> lo(s.dim, INFINITY), hi(s.dim, -INFINITY);
  for (std::size_t i = 0; i < s.n; ++i)
    for (std::size_t a = 0; a < s.dim; ++a) {
      lo[a] = std::min(lo[a], s.base[i * s.dim + a]);
      hi[a] = std::max(hi[a], s.base[i * s.dim + a]);
    }
  for (std::size_t a = 0; a < s.dim; ++a) in.centre.push_back(lo[a] + (hi[a] - lo[a]) / 2);
  if (s.bytes) in.bytes.assign(s.base.begin(), s.base.end());  // the values are integers in [0, 255]
  return in;
}

void run_set(const Set& s, std::size_t k, std::size_t reps, int& status) {
  std::printf("\n## %s: %s; n %zu, %zu queries, %zu-D, k %zu%s\n\n", s.name.c_str(), s.description.c_str(),
              s.n, s.nq, s.dim, k, s.bytes ? ", kdspace on byte rows" : "");
  std::fflush(stdout);
  const ScanInput in = scan_input(s);
  std::vector<kdspace::Neighbor<float>> ours(s.nq * k);
  auto run_kdspace = [&](kdspace::detail::ScanProfile* profile) {
    kdspace::detail::ScanData<float> data{
        s.bytes ? nullptr : s.base.data(),   in.order.data(), s.n,     s.dim, in.centre.data(),
        s.bytes ? in.bytes.data() : nullptr, profile,         g_widest};
    kdspace::detail::blocked_scan_knn_l2(data, s.queries.data(), s.nq, k, ours.data());
  };
  faiss::IndexFlatL2 index(static_cast<faiss::Index::idx_t>(s.dim));
  index.add(static_cast<faiss::Index::idx_t>(s.n), s.base.data());
  std::vector<float> faiss_dist(s.nq * k);
  std::vector<faiss::Index::idx_t> faiss_ids(s.nq * k);
  auto run_faiss = [&] {
    index.search(static_cast<faiss::Index::idx_t>(s.nq), s.queries.data(),
                 static_cast<faiss::Index::idx_t>(k), faiss_dist.data(), faiss_ids.data());
  };
  std::vector<double> t_ours, t_faiss;
  for (std::size_t r = 0; r < reps; ++r) {
    double t0 = now_seconds();
    run_kdspace(nullptr);
    t_ours.push_back(now_seconds() - t0);
    t0 = now_seconds();
    run_faiss();
    t_faiss.push_back(now_seconds() - t0);
    std::fprintf(stderr, "%s rep %zu: kdspace %.3f s, faiss %.3f s\n", s.name.c_str(), r, t_ours.back(),
                 t_faiss.back());
  }
  // kdspace bit for bit against brute force on 50 queries spread over the set.
  std::size_t wrong = 0, checked = 0;
  for (std::size_t j = 0; j < s.nq; j += std::max<std::size_t>(1, s.nq / 50), ++checked) {
    const auto ref = kdspace::brute_force_knn(s.base.data(), s.n, s.dim, s.queries.data() + j * s.dim, k);
    if (!std::equal(ref.begin(), ref.end(), ours.begin() + static_cast<long>(j * k))) ++wrong;
  }
  if (wrong) status = 1;
  // FAISS against kdspace: squared distances within 1e-5 at every rank (relative; absolute below 1).
  std::size_t faiss_off = 0;
  for (std::size_t i = 0; i < s.nq * k; ++i) {
    const double exact = static_cast<double>(ours[i].distance) * ours[i].distance;
    if (std::abs(static_cast<double>(faiss_dist[i]) - exact) > 1e-5 * std::max(1.0, exact)) ++faiss_off;
  }
  kdspace::detail::ScanProfile profile;
  run_kdspace(&profile);
  const double total = profile.check_s + profile.prepare_s + profile.product_s + profile.recheck_s;
  const double q_ours = static_cast<double>(s.nq) / median(t_ours),
               q_faiss = static_cast<double>(s.nq) / median(t_faiss);
  std::printf("| library | q/s (1 thread) | median s |\n|---|---:|---:|\n");
  std::printf("| kdspace blocked scan | %.0f | %.4f |\n| FAISS IndexFlatL2 | %.0f | %.4f |\n", q_ours,
              median(t_ours), q_faiss, median(t_faiss));
  std::printf("| **kdspace ÷ FAISS** | **%.2f** | |\n\n", q_ours / q_faiss);
  std::printf(
      "kdspace exact against brute force on %zu queries: %s. FAISS's squared distances off by more than 1e-5 "
      "(relative; absolute below 1): %zu of %zu.\n",
      checked, wrong ? "DIFFERENT" : "bit for bit", faiss_off, s.nq * k);
  std::printf(
      "kdspace phases (%s path): data checks %.0f%%, packing %.0f%%, product + bound %.0f%%, re-check + "
      "ranking %.0f%%; %.1f "
      "candidates a query (%.4f of the points)\n",
      profile.integer_path ? "16-bit integer" : "float estimate + bound", 100 * profile.check_s / total,
      100 * profile.prepare_s / total, 100 * profile.product_s / total, 100 * profile.recheck_s / total,
      static_cast<double>(profile.candidates) / static_cast<double>(s.nq),
      static_cast<double>(profile.candidates) / static_cast<double>(s.nq * s.n));
  std::printf(
      "{\"bench\":\"scan\",\"set\":\"%s\",\"n\":%zu,\"nq\":%zu,\"dim\":%zu,\"k\":%zu,\"kdspace_qps\":%.1f,"
      "\"faiss_qps\":%.1f,\"ratio\":%.3f,\"exact\":%s,\"candidates_per_query\":%.2f}\n",
      s.name.c_str(), s.n, s.nq, s.dim, k, q_ours, q_faiss, q_ours / q_faiss, wrong ? "false" : "true",
      static_cast<double>(profile.candidates) / static_cast<double>(s.nq));
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  std::string images;
  std::size_t n = 196000, nq = 2000, k = 10, reps = 5;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "kdspace-scan-bench: error: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    auto count = [&]() {
      const std::optional<std::size_t> c = kdspace::bench::positive_count(value(), 1e9);
      if (!c) {
        std::fprintf(stderr, "kdspace-scan-bench: error: %s needs a whole number >= 1\n", a.c_str());
        std::exit(2);
      }
      return *c;
    };
    if (a == "--images") {
      images = value();
    } else if (a == "--n") {
      n = count();
    } else if (a == "--queries") {
      nq = count();
    } else if (a == "--k") {
      k = count();
    } else if (a == "--reps") {
      reps = count();
    } else if (a == "--clock") {
      g_cpu_clock = value() == "cpu";
    } else if (a == "--kernel") {
      const std::string v = value();
      if (v == "avx512")
        g_widest = kdspace::detail::ScanKernel::avx512;
      else if (v == "avx2")
        g_widest = kdspace::detail::ScanKernel::avx2;
      else if (v == "portable")
        g_widest = kdspace::detail::ScanKernel::portable;
      else {
        std::fprintf(stderr, "kdspace-scan-bench: error: --kernel is avx512, avx2 or portable\n");
        return 2;
      }
    } else {
      std::fprintf(stderr,
                   "usage: kdspace-scan-bench [--images DIR] [--n N] [--queries Q] [--k K] [--reps R] "
                   "[--clock wall|cpu] [--kernel avx512|avx2|portable]\n");
      return 2;
    }
  }
  std::printf(
      "# kdspace-scan-bench: exact %zu-NN batches, 1 thread; kdspace: the widest kernel the processor has, "
      "up "
      "to %s; FAISS's sgemm from %s; %s time\n",
      k, kernel_name(), one_thread().c_str(), g_cpu_clock ? "CPU" : "wall");
  int status = 0;
  std::vector<Set> sets;
  if (!images.empty()) {
    const kdspace_bench::AnnData photos = kdspace_bench::photos(images, static_cast<std::size_t>(-1), nq);
    for (bool bytes : {false, true})
      sets.push_back({bytes ? "images128d-bytes" : "images128d", photos.description, photos.dim, photos.n(),
                      photos.nq(), photos.base, photos.queries, bytes});
  }
  const kdspace_bench::AnnData clustered = kdspace_bench::clustered(n, nq, 128);
  sets.push_back({clustered.name, clustered.description, clustered.dim, clustered.n(), clustered.nq(),
                  clustered.base, clustered.queries, false});
  for (const Set& s : sets) {
    if (k == 0 || k > s.n) {
      std::fprintf(stderr, "kdspace-scan-bench: error: --k must be in [1, %zu]\n", s.n);
      return 2;
    }
    run_set(s, k, reps, status);
  }
  return status;
}
