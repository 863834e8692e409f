// kdspace-rays-bench: kdspace's BoxTree side by side with Embree 3 on identical boxes and rays, in
// one process.
//
// Contenders
//   kdspace          BoxTree with the default build (sah_nlogn, one thread); closest_hit_batch for
//                    closest hits, any_hit_batch over [1e-4, 1] for shadow rays. The batches trace
//                    eight rays at a time (AVX2; else four) where neighbours' directions share their
//                    signs (packets: camera and shadow rays mostly), the other rays in streams of
//                    one direction octant each (lib/rays/trace_stream.cpp: random rays).
//   embree-user-Q    Embree user geometry (RTC_GEOMETRY_TYPE_USER), one primitive per box: the bounds
//                    callback returns the box, the intersect callback runs kdspace's closed slab test
//                    (double precision from the float data, t rounded to float; a ray starting inside
//                    a box hits it at tnear; closest t, equal t to the smaller box index), the occluded
//                    callback the same test, ending the ray at its first box.
//   embree-tri-Q     Embree triangles (RTC_GEOMETRY_TYPE_TRIANGLE): each box as 12 triangles over its
//                    8 shared corners; box index = primID / 12.
//   Q is the scene build quality, medium (RTC_BUILD_QUALITY_MEDIUM) or high (RTC_BUILD_QUALITY_HIGH):
//   both for user geometry by default, medium for triangles (high, with its spatial splits, takes some
//   40 s a build on 1e6 boxes = 12e6 triangles on one thread; --tri-quality medium,high adds it).
//   Of the user-geometry variants the one with the higher geometric mean of its trace speeds is the
//   scene's peer, marked "(peer)" in the table and used in the summary.
// Embree traces with rtcIntersect1 / rtcOccluded1, one ray at a time through an RTCIntersectContext
// (its packet calls, rtcIntersect4/8/16, are not measured here). The Embree device is created with
// "threads=1": its builds run on one thread, as kdspace's default build does. For two threads both libraries
// spread the rays over two threads that take chunks of 256 rays from a shared counter (kdspace: the batches
// on 2 threads; Embree: the calling thread and one std::thread), so each traces about half and a costly part
// of the image does not leave one thread idle.
//
// Scenes
//   uniform, clustered   generate_boxes(n, kind, seed 1) in the unit cube, for each --sizes n.
//   mesh NAME            with --real DIR: the bounding boxes of the triangles of each mesh that
//                        bench/real_data/fetch.sh DIR lists (read by bench/real_data/mesh_io.hpp;
//                        scans without triangles are skipped): thin, elongated, overlapping boxes.
//   voxels NAME          with --real DIR: the voxels of a grid of --voxels R cells along the mesh's
//                        longest side that its surface passes through (rays_scenes.hpp): cubes sharing
//                        faces, coplanar faces everywhere.
// Rays (per scene)
//   primary   a 1024 x 768 camera outside the scene (fit_camera, primary_rays): closest hit.
//   random    1e6 rays from origins in the bounds grown by 10%, unit directions (random_rays, seed 2):
//             closest hit.
//   shadow    from each primary ray's hit point (kdspace's answer) towards a point light above and
//             beside the scene, over t in [1e-4, 1] (the light at t = 1): any hit, the occlusion
//             test of a renderer.
//
// Measured: the build (wall seconds, or with --cpu-time CPU seconds; everything from the boxes to a
// traceable structure; Embree: new scene, geometry, buffers, commit), memory (kdspace: memory_bytes();
// Embree: the bytes its device allocated for the scene, as reported by its memory monitor, plus for user
// geometry the 24-byte boxes the callbacks read), and speed in Mrays/s on 1 and 2 threads. Repetitions are
// interleaved across contenders (repetition loop outside, contenders inside); medians are reported. Profile
// (kdspace, after the repetitions, 1 thread): the tree (SAH cost, leaves, references per box, depth), per ray
// set the nodes visited and boxes tested per ray, and the time per ray cold (as measured) and hot: each ray
// traced twice in a row, the second time with its nodes and boxes in cache, so cold - hot is the time spent
// waiting for memory.
//
// Agreement (first repetition, 1 thread): each Embree variant's hit for every ray against kdspace's:
//   hit/miss      one hits, the other does not
//   t differs     both hit, |t_a - t_b| > 1e-4 * max(t_a, t_b) + 1e-6 * scene diagonal (closest hit)
//   near ties     both hit within that tolerance but not at the same float t, at different boxes:
//                 rounding. Embree's BVH traversal computes node entries in float, so it may cull a box
//                 the ray enters a rounding step before the hit it already has; triangles compute t in
//                 float, so coplanar faces of different boxes land here too.
//   ties          both hit at the same float t, at different boxes. kdspace resolves equal t to the
//                 smaller index; the user callback does too when Embree hands it both boxes, but
//                 Embree's BVH traversal may cull a node whose entry equals the current tfar, so the
//                 smaller index is not guaranteed there. (kdspace compares the double t and rounds
//                 afterwards; Embree keeps a float tfar: boxes a rounding step apart are ties to it.)
//                 For shadow rays any box will do: only hit/miss counts.
//   grazing       any other difference where the closer of the two hits only grazes its box: the ray's
//                 part inside that box (or, for a box one side reports and the other's slab test
//                 rejects, its miss) is at most 1e-5 of the scene diagonal long. A ray along an edge or
//                 a face, where kdspace's double slab test and Embree's float BVH (and triangle) tests
//                 may decide either way. Not counted in the other columns.
//   inside        rays whose kdspace hit has t = 0: the origin lies in (or on) a box. Triangles then
//                 hit the exit face or another box, so for the triangle variants these rays are
//                 counted here and left out of the other columns.
// The first three rays with hit/miss or t differs (and, for user geometry, near ties) per contender and
// ray set are printed on stderr.
// The exit status is 1 when a user-geometry variant disagrees beyond ties, near ties and grazing
// (hit/miss or t differs), or when a library's 2-thread answers differ from its 1-thread ones; 2 for a
// usage error.
//
// usage: kdspace-rays-bench [--sizes N,N,...] [--kinds uniform,clustered] [--real DIR] [--voxels R]
//                           [--only-real] [--reps R] [--rays M] [--image WxH] [--quality medium,high]
//                           [--tri-quality medium,high] [--robust] [--cpu-time] [--quick] [--counts]
//   --sizes     synthetic scene sizes in boxes (default 1000,100000,1000000; 1e5 is accepted)
//   --kinds     synthetic scene kinds (default uniform,clustered)
//   --real      a folder filled by bench/real_data/fetch.sh: adds the mesh and voxel scenes
//   --voxels    grid resolution of the voxel scenes (default 256; 0: no voxel scenes)
//   --only-real no synthetic scenes
//   --reps      repetitions (default 3)
//   --rays      random rays (default 1000000)
//   --image     primary rays: an image of W x H pixels (default 1024x768)
//   --quality   Embree build qualities for user geometry (default medium,high)
//   --tri-quality  Embree build qualities for triangles (default medium; "none": no triangles)
//   --robust    Embree scenes with RTC_SCENE_FLAG_ROBUST (names get "-robust"); default: no flags
//   --cpu-time  CPU seconds of the process (divided by the threads at work) instead of wall seconds:
//               for a machine shared with other jobs
//   --quick     sizes 1000,100000, 200000 random rays, a 512x384 image, 1 repetition (explicit options
//               still win)
//   --counts    no timing: per scene and ray set (primary, random) the boxes Embree's user geometry tests
//               per ray (callback calls) beside kdspace's nodes and boxes per ray, split into inner nodes,
//               leaves, empty leaves, references and distinct boxes (rays_counts.hpp)
//
// Output: per scene a markdown table, a profile line and an agreement table, then one JSON line per
// measurement ({"bench":"rays",...}); at the end a summary table of kdspace against the peer on every
// scene. Progress goes to stderr.
#include <embree3/rtcore.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <limits>
#include <memory>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

#include "kdspace/boxes/box_tree.hpp"
#include "kdspace/error.hpp"
#include "kdspace/rays/detail/slab.hpp"
#include "kdspace/rays/scene_gen.hpp"
#include "bench_args.hpp"
#include "rays_counts.hpp"
#include "rays_scenes.hpp"

namespace {

using kdspace::Box3f;
using kdspace::Hit;
using kdspace::Ray;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

/// --cpu-time: measure the CPU time of this process (divided by the threads at work) instead of wall
/// time. On a machine shared with other jobs, wall time also counts the time the others held the
/// cores; the figures of a quiet machine are wall times.
bool use_cpu_time = false;

double process_cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

/// Seconds of a measured step: wall seconds, or with --cpu-time CPU seconds / threads.
class Stopwatch {
 public:
  explicit Stopwatch(unsigned threads = 1)
      : threads_(threads), wall_(Clock::now()), cpu_(process_cpu_seconds()) {}
  double seconds() const {
    return use_cpu_time ? (process_cpu_seconds() - cpu_) / threads_ : seconds_since(wall_);
  }

 private:
  unsigned threads_;
  Clock::time_point wall_;
  double cpu_;
};
double dbl(std::size_t x) {
  return static_cast<double>(x);
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t mid = v.size() / 2;
  return v.size() % 2 ? v[mid] : 0.5 * (v[mid - 1] + v[mid]);
}

const char* kind_name(kdspace::SceneKind kind) {
  return kind == kdspace::SceneKind::uniform ? "uniform" : "clustered";
}
const char* quality_name(RTCBuildQuality q) {
  return q == RTC_BUILD_QUALITY_HIGH ? "high" : "medium";
}

// ---- options --------------------------------------------------------------------------------------

struct Options {
  std::vector<std::size_t> sizes{1000, 100000, 1000000};
  std::vector<kdspace::SceneKind> kinds{kdspace::SceneKind::uniform, kdspace::SceneKind::clustered};
  std::vector<RTCBuildQuality> user_qualities{RTC_BUILD_QUALITY_MEDIUM, RTC_BUILD_QUALITY_HIGH};
  std::vector<RTCBuildQuality> triangle_qualities{RTC_BUILD_QUALITY_MEDIUM};
  int reps = 3;
  std::size_t random_rays = 1000000;
  std::size_t width = 1024, height = 768;
  bool robust = false;   ///< RTC_SCENE_FLAG_ROBUST on the Embree scenes
  std::string real_dir;  ///< fetch.sh's folder, or "" for no real scenes
  std::size_t voxel_resolution = 256;
  bool synthetic = true;
  bool cpu_time = false;
  bool counts = false;  ///< --counts: work per ray only (print_counts), no timing
};

[[noreturn]] void usage(const char* problem) {
  if (problem) std::fprintf(stderr, "kdspace-rays-bench: %s\n", problem);
  std::fprintf(
      stderr,
      "usage: kdspace-rays-bench [--sizes N,N,...] [--kinds uniform,clustered] [--real DIR] [--voxels R]\n"
      "                          [--only-real] [--reps R] [--rays M] [--image WxH] [--quality medium,high]\n"
      "                          [--tri-quality medium,high] [--robust] [--cpu-time] [--quick] [--counts]\n");
  std::exit(2);
}

using kdspace::bench::split_list;

std::size_t parse_count(const std::string& text) {
  if (const auto count = kdspace::bench::positive_count(text, 1e12)) return *count;
  usage(("not a positive whole number: " + text).c_str());
}

Options parse(int argc, char** argv) {
  Options o;
  bool quick = false, sizes_given = false, rays_given = false, reps_given = false, image_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) usage((a + " needs a value").c_str());
      return argv[++i];
    };
    if (a == "--sizes") {
      o.sizes.clear();
      for (const std::string& s : split_list(next(), ',')) o.sizes.push_back(parse_count(s));
      if (o.sizes.empty()) usage("--sizes: no size given");
      sizes_given = true;
    } else if (a == "--kinds") {
      o.kinds.clear();
      for (const std::string& s : split_list(next(), ',')) {
        if (s == "uniform") {
          o.kinds.push_back(kdspace::SceneKind::uniform);
        } else if (s == "clustered") {
          o.kinds.push_back(kdspace::SceneKind::clustered);
        } else {
          usage(("unknown scene kind: " + s).c_str());
        }
      }
      if (o.kinds.empty()) usage("--kinds: no kind given");
    } else if (a == "--quality" || a == "--tri-quality") {
      std::vector<RTCBuildQuality>& qualities = a == "--quality" ? o.user_qualities : o.triangle_qualities;
      qualities.clear();
      const std::string list = next();
      if (a == "--tri-quality" && list == "none") continue;
      for (const std::string& s : split_list(list, ',')) {
        if (s == "medium") {
          qualities.push_back(RTC_BUILD_QUALITY_MEDIUM);
        } else if (s == "high") {
          qualities.push_back(RTC_BUILD_QUALITY_HIGH);
        } else {
          usage(("unknown build quality: " + s).c_str());
        }
      }
      if (qualities.empty() && a == "--quality") usage("--quality: no quality given");
    } else if (a == "--reps") {
      o.reps = static_cast<int>(std::min<std::size_t>(parse_count(next()), 1000));
      reps_given = true;
    } else if (a == "--rays") {
      o.random_rays = parse_count(next());
      rays_given = true;
    } else if (a == "--image") {
      const std::vector<std::string> wh = split_list(next(), 'x');
      if (wh.size() != 2) usage("--image wants WxH, e.g. 1024x768");
      o.width = parse_count(wh[0]);
      o.height = parse_count(wh[1]);
      image_given = true;
    } else if (a == "--robust") {
      o.robust = true;
    } else if (a == "--real") {
      o.real_dir = next();
    } else if (a == "--voxels") {
      const std::string r = next();
      o.voxel_resolution = r == "0" ? 0 : parse_count(r);
    } else if (a == "--only-real") {
      o.synthetic = false;
    } else if (a == "--cpu-time") {
      o.cpu_time = true;
    } else if (a == "--counts") {
      o.counts = true;
    } else if (a == "--quick") {
      quick = true;
    } else if (a == "--help" || a == "-h") {
      usage(nullptr);
    } else {
      usage(("unknown option: " + a).c_str());
    }
  }
  if (quick) {
    if (!sizes_given) o.sizes = {1000, 100000};
    if (!rays_given) o.random_rays = 200000;
    if (!reps_given) o.reps = 1;
    if (!image_given) o.width = 512, o.height = 384;
  }
  return o;
}

// ---- Embree ---------------------------------------------------------------------------------------

/// Bytes the Embree device holds: the memory monitor adds allocations and subtracts frees.
std::atomic<std::int64_t> embree_bytes{0};

bool count_embree_bytes(void* /*user*/, ssize_t bytes, bool /*post*/) {
  embree_bytes += static_cast<std::int64_t>(bytes);
  return true;
}

void report_embree_error(void* /*user*/, RTCError code, const char* message) {
  std::fprintf(stderr, "kdspace-rays-bench: Embree error %d: %s\n", static_cast<int>(code),
               message ? message : "");
  std::exit(1);
}

/// A ray prepared once for the user-geometry callbacks, as kdspace prepares it for its traversal.
/// Embree hands the callbacks the RTCIntersectContext given to rtcIntersect1 / rtcOccluded1; this
/// struct begins with one (standard layout), so the callbacks reach the prepared ray through it
/// (Embree's documented way of passing per-ray data to callbacks).
struct RayContext {
  RTCIntersectContext embree;
  kdspace::detail::PreparedRay ray;   // the very preparation and slab test of kdspace's traversal
  std::int32_t occluder = Hit::none;  ///< the box that ended a shadow ray
  std::uint32_t callbacks = 0;        ///< boxes Embree handed the callbacks (--counts)

  explicit RayContext(const Ray& r) : ray(r) { rtcInitIntersectContext(&embree); }
};
static_assert(std::is_standard_layout<RayContext>::value, "RayContext must start with the Embree context");

using kdspace::detail::clip_to_box;

void box_bounds(const RTCBoundsFunctionArguments* args) {
  const Box3f& b = static_cast<const Box3f*>(args->geometryUserPtr)[args->primID];
  RTCBounds* out = args->bounds_o;
  out->lower_x = b.lo[0];
  out->lower_y = b.lo[1];
  out->lower_z = b.lo[2];
  out->upper_x = b.hi[0];
  out->upper_y = b.hi[1];
  out->upper_z = b.hi[2];
}

[[noreturn]] void not_single(unsigned n) {
  std::fprintf(stderr, "kdspace-rays-bench: user geometry called with N = %u (only rtc*1 calls are used)\n",
               n);
  std::abort();
}

/// rtcIntersect1 calls this with N = 1 and our RayContext; anything else is not what we measure.
void box_intersect(const RTCIntersectFunctionNArguments* args) {
  if (args->N != 1) not_single(args->N);
  if (args->valid[0] == 0) return;
  const Box3f& b = static_cast<const Box3f*>(args->geometryUserPtr)[args->primID];
  auto* context = reinterpret_cast<RayContext*>(args->context);
  ++context->callbacks;
  const kdspace::detail::PreparedRay& ray = context->ray;
  RTCRayN* rays = RTCRayHitN_RayN(args->rayhit, 1);
  RTCHitN* hits = RTCRayHitN_HitN(args->rayhit, 1);
  float& tfar = RTCRayN_tfar(rays, 1, 0);
  double t_near = RTCRayN_tnear(rays, 1, 0), t_far = tfar;
  if (!clip_to_box(b, ray, t_near, t_far)) return;
  constexpr double largest = std::numeric_limits<float>::max();
  const auto t = static_cast<float>(t_near > largest ? largest : t_near);
  unsigned& hit_geometry = RTCHitN_geomID(hits, 1, 0);
  unsigned& hit_box = RTCHitN_primID(hits, 1, 0);
  // Here t <= tfar (rounding to float keeps the order). Closest t; at equal t the smaller box index,
  // or any box while there is no hit yet (a hit at exactly the ray's initial tfar).
  if (!(t < tfar || hit_geometry == RTC_INVALID_GEOMETRY_ID || args->primID < hit_box)) return;
  tfar = t;
  RTCHitN_Ng_x(hits, 1, 0) = 0;
  RTCHitN_Ng_y(hits, 1, 0) = 0;
  RTCHitN_Ng_z(hits, 1, 0) = 0;
  RTCHitN_u(hits, 1, 0) = 0;
  RTCHitN_v(hits, 1, 0) = 0;
  hit_box = args->primID;
  hit_geometry = args->geomID;
  RTCHitN_instID(hits, 1, 0, 0) = args->context->instID[0];
}

/// rtcOccluded1: the ray ends at the first box it hits over [tnear, tfar] (tfar = -inf says so).
void box_occluded(const RTCOccludedFunctionNArguments* args) {
  if (args->N != 1) not_single(args->N);
  if (args->valid[0] == 0) return;
  const Box3f& b = static_cast<const Box3f*>(args->geometryUserPtr)[args->primID];
  auto* context = reinterpret_cast<RayContext*>(args->context);
  ++context->callbacks;
  float& tfar = RTCRayN_tfar(args->ray, 1, 0);
  double t_near = RTCRayN_tnear(args->ray, 1, 0), t_far = tfar;
  if (!clip_to_box(b, context->ray, t_near, t_far)) return;
  tfar = -std::numeric_limits<float>::infinity();
  context->occluder = static_cast<std::int32_t>(args->primID);
}

RTCRay make_ray(const Ray& ray, float t_min, float t_max) {
  RTCRay r;
  r.org_x = ray.origin[0];
  r.org_y = ray.origin[1];
  r.org_z = ray.origin[2];
  r.tnear = t_min;
  r.dir_x = ray.direction[0];
  r.dir_y = ray.direction[1];
  r.dir_z = ray.direction[2];
  r.time = 0;
  r.tfar = t_max;
  r.mask = 0xffffffffu;
  r.id = 0;
  r.flags = 0;
  return r;
}

RTCRayHit make_rayhit(const Ray& ray) {
  RTCRayHit rh;
  rh.ray = make_ray(ray, 0, std::numeric_limits<float>::infinity());
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  return rh;
}

// ---- ray sets -------------------------------------------------------------------------------------

/// Rays and what is asked of them: the closest hit over [0, inf), or any hit over [t_min, t_max].
struct RaySet {
  const char* name;
  bool any_hit;
  std::vector<Ray> rays;
  float t_min = 0, t_max = std::numeric_limits<float>::infinity();
};

/// Shadow rays start this far along (in units of the way to the light) from their hit point, past
/// the box they start on.
constexpr float shadow_t_min = 1e-4f;

/// From each hit point of `primary` (hits[i]) towards a point light above and beside the scene
/// (from -x, +y, above; the camera looks from +x, -y), over t in [shadow_t_min, 1].
std::vector<Ray> shadow_rays(const std::vector<Ray>& primary, const std::vector<Hit>& hits,
                             const Box3f& bounds) {
  std::array<double, 3> light{};
  const double factor[3] = {-0.3, 1.5, 2.0};  // the light at lo + factor * extent
  for (int a = 0; a < 3; ++a)
    light[a] = bounds.lo[a] + factor[a] * (static_cast<double>(bounds.hi[a]) - bounds.lo[a]);
  std::vector<Ray> rays;
  for (std::size_t i = 0; i < primary.size(); ++i) {
    if (!hits[i].hit()) continue;
    Ray r;
    for (int a = 0; a < 3; ++a) {
      r.origin[a] =
          static_cast<float>(primary[i].origin[a] + static_cast<double>(hits[i].t) * primary[i].direction[a]);
      r.direction[a] = static_cast<float>(light[a] - r.origin[a]);
    }
    if (kdspace::ray_problem(r).empty()) rays.push_back(r);
  }
  return rays;
}

// ---- spreading rays over threads ------------------------------------------------------------------

/// Calls body(begin, end) over [0, n) in chunks of 256 taken from a shared counter, on the calling
/// thread and threads - 1 std::threads: the scheme of kdspace's closest_hit_batch.
template <class Body>
void for_chunks(std::size_t n, unsigned threads, const Body& body) {
  constexpr std::size_t chunk = 256;
  if (threads <= 1) {
    body(std::size_t{0}, n);
    return;
  }
  std::atomic<std::size_t> next{0};
  auto run = [&] {
    for (;;) {
      const std::size_t begin = next.fetch_add(chunk);
      if (begin >= n) return;
      body(begin, std::min(n, begin + chunk));
    }
  };
  std::vector<std::thread> helpers;
  for (unsigned t = 1; t < threads; ++t) helpers.emplace_back(run);
  run();
  for (std::thread& t : helpers) t.join();
}

// ---- contenders -----------------------------------------------------------------------------------

class Contender {
 public:
  virtual ~Contender() = default;
  virtual std::string name() const = 0;
  virtual const char* library() const = 0;
  virtual const char* quality() const { return ""; }
  virtual void build(const std::vector<Box3f>& boxes) = 0;
  /// The hits of a ray set: for any-hit sets, the box found (any) or a miss.
  virtual std::vector<Hit> trace(const RaySet& set, unsigned threads) const = 0;
  /// Frees what build made.
  virtual void release() = 0;
  /// Bytes held by the built structure (see the header comment).
  virtual std::size_t memory_bytes() const = 0;
};

class KdspaceContender final : public Contender {
 public:
  std::string name() const override { return "kdspace"; }
  const char* library() const override { return "kdspace"; }
  void build(const std::vector<Box3f>& boxes) override { tree_ = std::make_unique<kdspace::BoxTree>(boxes); }
  std::vector<Hit> trace(const RaySet& set, unsigned threads) const override {
    const kdspace::RayRange range{set.t_min, set.t_max};
    return set.any_hit ? tree_->any_hit_batch(set.rays, range, threads)
                       : tree_->closest_hit_batch(set.rays, range, threads);
  }
  void release() override { tree_.reset(); }
  std::size_t memory_bytes() const override { return tree_->memory_bytes(); }
  const kdspace::BoxTree& tree() const { return *tree_; }

 private:
  std::unique_ptr<kdspace::BoxTree> tree_;
};

class EmbreeContender final : public Contender {
 public:
  EmbreeContender(RTCDevice device, bool triangles, RTCBuildQuality quality, bool robust)
      : device_(device), triangles_(triangles), quality_(quality), robust_(robust) {}
  ~EmbreeContender() override { release(); }

  std::string name() const override {
    return std::string(library()) + "-" + quality_name(quality_) + (robust_ ? "-robust" : "");
  }
  const char* library() const override { return triangles_ ? "embree-tri" : "embree-user"; }
  const char* quality() const override { return quality_name(quality_); }

  void build(const std::vector<Box3f>& boxes) override {
    release();
    const std::int64_t bytes_before = embree_bytes.load();
    scene_ = rtcNewScene(device_);
    rtcSetSceneBuildQuality(scene_, quality_);
    if (robust_) rtcSetSceneFlags(scene_, RTC_SCENE_FLAG_ROBUST);
    RTCGeometry geometry;
    if (triangles_) {
      geometry = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
      fill_triangles(geometry, boxes);
    } else {
      geometry = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_USER);
      rtcSetGeometryUserPrimitiveCount(geometry, static_cast<unsigned>(boxes.size()));
      rtcSetGeometryUserData(geometry, const_cast<Box3f*>(boxes.data()));
      rtcSetGeometryBoundsFunction(geometry, box_bounds, nullptr);
      rtcSetGeometryIntersectFunction(geometry, box_intersect);
      rtcSetGeometryOccludedFunction(geometry, box_occluded);
    }
    rtcSetGeometryBuildQuality(geometry, quality_);
    rtcCommitGeometry(geometry);
    rtcAttachGeometry(scene_, geometry);
    rtcReleaseGeometry(geometry);
    rtcCommitScene(scene_);
    bytes_ = static_cast<std::size_t>(std::max<std::int64_t>(0, embree_bytes.load() - bytes_before));
    // The user-geometry callbacks read the application's boxes: count them as part of the structure.
    if (!triangles_) bytes_ += boxes.size() * sizeof(Box3f);
  }

  std::vector<Hit> trace(const RaySet& set, unsigned threads) const override {
    std::vector<Hit> hits(set.rays.size());
    const RTCScene scene = scene_;
    const bool triangles = triangles_;
    for_chunks(set.rays.size(), threads, [&](std::size_t begin, std::size_t end) {
      std::uint64_t callbacks = 0;
      for (std::size_t i = begin; i < end; ++i) {
        const Ray& ray = set.rays[i];
        if (set.any_hit) {
          RTCRay r = make_ray(ray, set.t_min, set.t_max);
          RayContext context(ray);
          rtcOccluded1(scene, &context.embree, &r);
          callbacks += context.callbacks;
          // Triangles do not say which box ended the ray: box 0 stands for "some box" there.
          if (r.tfar < 0) hits[i] = Hit{triangles ? 0 : context.occluder, 0};
          continue;
        }
        RTCRayHit rh = make_rayhit(ray);
        if (triangles) {
          RTCIntersectContext context;
          rtcInitIntersectContext(&context);
          rtcIntersect1(scene, &context, &rh);
          if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID)
            hits[i] = Hit{static_cast<std::int32_t>(rh.hit.primID / 12), rh.ray.tfar};
        } else {
          RayContext context(ray);  // the reciprocal direction etc., once per ray, as kdspace does
          rtcIntersect1(scene, &context.embree, &rh);
          callbacks += context.callbacks;
          if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID)
            hits[i] = Hit{static_cast<std::int32_t>(rh.hit.primID), rh.ray.tfar};
        }
      }
      callbacks_ += callbacks;
    });
    return hits;
  }
  /// Boxes handed to the user-geometry callbacks by all trace() calls so far (one box, one call).
  std::uint64_t callbacks() const { return callbacks_.load(); }

  void release() override {
    if (scene_) rtcReleaseScene(scene_);
    scene_ = nullptr;
  }
  std::size_t memory_bytes() const override { return bytes_; }

 private:
  /// Box i: corners 8i + (x is hi) + 2 (y is hi) + 4 (z is hi); two triangles per face, 12i .. 12i + 11.
  static void fill_triangles(RTCGeometry geometry, const std::vector<Box3f>& boxes) {
    auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
        geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 8 * boxes.size()));
    auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), 12 * boxes.size()));
    static constexpr unsigned faces[12][3] = {
        {0, 4, 6}, {0, 6, 2},  // x = lo
        {1, 3, 7}, {1, 7, 5},  // x = hi
        {0, 1, 5}, {0, 5, 4},  // y = lo
        {2, 6, 7}, {2, 7, 3},  // y = hi
        {0, 2, 3}, {0, 3, 1},  // z = lo
        {4, 5, 7}, {4, 7, 6},  // z = hi
    };
    for (std::size_t i = 0; i < boxes.size(); ++i) {
      const Box3f& b = boxes[i];
      for (unsigned corner = 0; corner < 8; ++corner) {
        float* v = vertices + 3 * (8 * i + corner);
        v[0] = (corner & 1u) ? b.hi[0] : b.lo[0];
        v[1] = (corner & 2u) ? b.hi[1] : b.lo[1];
        v[2] = (corner & 4u) ? b.hi[2] : b.lo[2];
      }
      const auto base = static_cast<unsigned>(8 * i);
      for (unsigned f = 0; f < 12; ++f)
        for (unsigned k = 0; k < 3; ++k) indices[3 * (12 * i + f) + k] = base + faces[f][k];
    }
  }

  RTCDevice device_;
  bool triangles_;
  RTCBuildQuality quality_;
  bool robust_;
  RTCScene scene_ = nullptr;
  std::size_t bytes_ = 0;
  mutable std::atomic<std::uint64_t> callbacks_{0};
};

// ---- agreement ------------------------------------------------------------------------------------

struct Agreement {
  std::size_t rays = 0;  ///< rays compared in the columns below
  std::size_t hit_miss = 0;
  std::size_t t_differs = 0;
  std::size_t near_ties = 0;
  std::size_t ties = 0;
  std::size_t grazing = 0;  ///< differences where the closer of the two hits only grazes its box
  std::size_t inside = 0;   ///< rays whose kdspace hit is at t = 0
  bool inside_excluded = false;
  std::size_t threads_differ = 0;  ///< rays whose 2-thread answer differs from the 1-thread one

  std::size_t real() const { return hit_miss + t_differs + threads_differ; }
};

/// Length (along the ray, in scene units) of the part of the ray over [t_min, t_max] inside the box:
/// negative when the ray misses it, by about how far; -inf when the ray runs parallel to a slab
/// outside it.
double segment_in_box(const Box3f& box, const Ray& ray, double t_min, double t_max) {
  const kdspace::detail::PreparedRay prepared(ray);
  double t_near = t_min, t_far = t_max;
  for (int a = 0; a < 3; ++a)
    if (prepared.parallel[a] && (prepared.origin[a] < box.lo[a] || prepared.origin[a] > box.hi[a]))
      return -std::numeric_limits<double>::infinity();
  clip_to_box(box, prepared, t_near, t_far);
  const double length = std::sqrt(static_cast<double>(ray.direction[0]) * ray.direction[0] +
                                  static_cast<double>(ray.direction[1]) * ray.direction[1] +
                                  static_cast<double>(ray.direction[2]) * ray.direction[2]);
  return (t_far - t_near) * length;
}

/// Counts how `other` differs from `reference` (kdspace's hits) on a ray set. A difference whose
/// closer hit only grazes its box (the ray's part inside it, or its miss distance, is at most `graze`
/// long: a ray along an edge or a face, where float and double arithmetic may decide either way) is
/// counted as grazing. For any-hit sets only hit or miss counts. The first few rays of each kind of
/// difference go to stderr with `label`: hit/miss and t differs, and near ties when `exact` (the user
/// geometry, whose t is computed as kdspace's is; triangles differ in rounding, so coplanar faces of
/// different boxes are expected there).
Agreement compare(const std::vector<Hit>& reference, const std::vector<Hit>& other, const RaySet& set,
                  const std::vector<Box3f>& boxes, double graze, bool exclude_inside, bool exact,
                  const std::string& label) {
  Agreement g;
  g.inside_excluded = exclude_inside;
  auto show = [&](const char* what, std::size_t count, std::size_t i) {
    if (count > 3) return;
    const Ray& r = set.rays[i];
    std::fprintf(
        stderr,
        "  %s: %s, ray %zu (origin %.9g %.9g %.9g, direction %.9g %.9g %.9g): kdspace box %d t %.9g, "
        "other box %d t %.9g\n",
        label.c_str(), what, i, r.origin[0], r.origin[1], r.origin[2], r.direction[0], r.direction[1],
        r.direction[2], reference[i].box, reference[i].t, other[i].box, other[i].t);
  };
  auto close = [&](float a, float b) {
    const double da = a, db = b;
    return std::abs(da - db) <= 1e-4 * std::max(std::abs(da), std::abs(db)) + graze / 10;
  };
  for (std::size_t i = 0; i < reference.size(); ++i) {
    const Hit& a = reference[i];
    const Hit& b = other[i];
    const bool inside = !set.any_hit && a.hit() && a.t == 0;
    if (inside) ++g.inside;
    if (inside && exclude_inside) continue;
    ++g.rays;
    if (a.hit() == b.hit() && (set.any_hit || !a.hit())) continue;  // same answer
    if (a.hit() && b.hit()) {
      if (a.box == b.box && close(a.t, b.t)) continue;  // agree
      if (a.box != b.box && a.t == b.t) {
        ++g.ties;
        continue;
      }
    }
    // The box to check for grazing: the closer hit's, or for an any-hit difference the one reported
    // (triangles do not say which, so then only kdspace's).
    const Hit& closer = a.hit() && (!b.hit() || a.t <= b.t || set.any_hit) ? a : b;
    const bool known = closer.hit() && !(set.any_hit && &closer == &b && !exact);
    const double length =
        known ? segment_in_box(boxes[static_cast<std::size_t>(closer.box)], set.rays[i], set.t_min, set.t_max)
              : std::numeric_limits<double>::infinity();
    if (std::abs(length) <= graze) {
      ++g.grazing;
    } else if (a.hit() != b.hit()) {
      show("hit/miss", ++g.hit_miss, i);
    } else if (!close(a.t, b.t)) {
      show("t differs", ++g.t_differs, i);
    } else {
      ++g.near_ties;
      if (exact) show("near tie", g.near_ties, i);
    }
  }
  return g;
}

std::size_t count_different(const std::vector<Hit>& a, const std::vector<Hit>& b) {
  std::size_t n = 0;
  for (std::size_t i = 0; i < a.size(); ++i) n += a[i] != b[i];
  return n;
}

// ---- one scene ------------------------------------------------------------------------------------

struct Scene {
  std::string name;  ///< "uniform", "clustered", "mesh bunny00", "voxels bunny00"
  std::string kind;  ///< uniform, clustered, mesh, voxels
  std::vector<Box3f> boxes;
};

/// The measurements of one contender over the repetitions: [ray set][threads - 1].
struct Samples {
  std::vector<double> build_s;
  std::array<std::array<std::vector<double>, 2>, 3> mrays;
  std::size_t memory_bytes = 0;
  std::array<Agreement, 3> agreement;  ///< per ray set, against kdspace (unused for kdspace)

  double speed(std::size_t set, int threads_index) const { return median(mrays[set][threads_index]); }
  double geometric_mean_speed(std::size_t sets) const {
    double log_sum = 0;
    for (std::size_t s = 0; s < sets; ++s)
      for (int t = 0; t < 2; ++t) log_sum += std::log(std::max(speed(s, t), 1e-300));
    return std::exp(log_sum / static_cast<double>(2 * sets));
  }
};

/// kdspace against the peer on one scene, for the summary.
struct SceneSummary {
  std::string scene;
  std::size_t boxes = 0;
  std::string peer;
  double build_kd = 0, build_peer = 0;
  std::array<double, 3> kd{}, other{};  ///< 1-thread Mrays/s per ray set
};

std::string format_ratio(double kd, double other) {
  if (!(other > 0)) return "-";
  char text[32];
  std::snprintf(text, sizeof text, "%.2f", kd / other);
  return text;
}

Box3f scene_bounds(const std::vector<Box3f>& boxes) {
  Box3f bounds;
  bounds.lo.fill(std::numeric_limits<float>::infinity());
  bounds.hi.fill(-std::numeric_limits<float>::infinity());
  for (const Box3f& b : boxes)
    for (int a = 0; a < 3; ++a) {
      bounds.lo[a] = std::min(bounds.lo[a], b.lo[a]);
      bounds.hi[a] = std::max(bounds.hi[a], b.hi[a]);
    }
  return bounds;
}

/// One row of the profile: the work per ray and the time per ray cold (each ray once, one call a
/// ray) and hot (each ray traced twice in a row: the second trace finds its nodes and boxes in
/// cache, so cold - hot is the time spent waiting for memory).
void print_profile_row(const Scene& scene, const kdspace::BoxTree& tree, const RaySet& set,
                       const std::string& name) {
  if (set.rays.empty()) return;
  kdspace::RayStats stats;
  auto trace = [&](const Ray& r) {
    if (set.any_hit)
      tree.any_hit(r, set.t_min, set.t_max, &stats);
    else
      tree.closest_hit(r, set.t_min, set.t_max, &stats);
  };
  const Stopwatch once;
  for (const Ray& r : set.rays) trace(r);
  const double cold = once.seconds() * 1e9 / dbl(set.rays.size());
  const kdspace::RayStats per_ray = stats;
  const Stopwatch twice;
  for (const Ray& r : set.rays) {
    trace(r);
    trace(r);
  }
  const double hot = twice.seconds() * 1e9 / dbl(set.rays.size()) - cold;
  std::printf("| %s | %zu | %.2f | %.2f | %.1f | %.1f |\n", name.c_str(), set.rays.size(),
              per_ray.nodes_visited_per_ray(), per_ray.boxes_tested_per_ray(), cold, hot);
  std::printf(
      "{\"bench\":\"rays-profile\",\"scene\":\"%s\",\"boxes\":%zu,\"rays\":\"%s\",\"count\":%zu,"
      "\"sah_cost\":%.4f,\"nodes_per_ray\":%.4f,\"boxes_per_ray\":%.4f,\"cold_ns\":%.2f,\"hot_ns\":%.2f}\n",
      scene.name.c_str(), scene.boxes.size(), name.c_str(), set.rays.size(), tree.stats().sah_cost,
      per_ray.nodes_visited_per_ray(), per_ray.boxes_tested_per_ray(), cold, hot);
}

/// kdspace's profile on one scene (1 thread): its tree and, per ray set, the work and time per ray
/// (print_profile_row); the closest-hit sets also split into the rays that hit and those that miss,
/// which walk the tree very differently (a ray that hits crosses the finely cut space around the
/// surface).
void print_profile(const Scene& scene, const std::array<RaySet, 3>& sets) {
  const kdspace::BoxTree tree(scene.boxes);
  const kdspace::BoxTreeStats& t = tree.stats();
  std::printf(
      "\nkdspace profile: SAH cost %.2f, %zu nodes, %zu leaves (%zu empty), depth %zu, %.2f references "
      "per box, %.1f MB.\n\n",
      t.sah_cost, t.nodes, t.leaves, t.empty_leaves, t.depth, t.references_per_box,
      dbl(tree.memory_bytes()) / 1e6);
  std::printf(
      "| rays | count | nodes / ray | boxes tested / ray | ns / ray cold | ns / ray hot "
      "|\n|---|---:|---:|---:|---:|---:|\n");
  for (const RaySet& set : sets) {
    print_profile_row(scene, tree, set, set.name);
    if (set.any_hit) continue;
    RaySet hitting{set.name, false, {}, set.t_min, set.t_max}, missing = hitting;
    for (const Ray& r : set.rays)
      (tree.closest_hit(r, set.t_min, set.t_max).hit() ? hitting : missing).rays.push_back(r);
    print_profile_row(scene, tree, hitting, std::string(set.name) + ", hitting");
    print_profile_row(scene, tree, missing, std::string(set.name) + ", missing");
  }
}

/// --counts: the work per ray on one scene, without timing. Embree: the boxes its BVH hands the
/// user-geometry callback (one call, one box); kdspace: the library's own counters (RayStats) and a
/// walk of its tree in the same order (rays_counts.hpp) that splits the work into inner nodes, leaves,
/// empty leaves, box references and distinct boxes.
void print_counts(const Options& o, const Scene& scene, RTCDevice device) {
  const Box3f bounds = scene_bounds(scene.boxes);
  const std::array<RaySet, 2> sets{
      RaySet{"primary", false,
             kdspace::primary_rays(kdspace::fit_camera(bounds, dbl(o.width) / dbl(o.height)), o.width,
                                   o.height)},
      RaySet{"random", false, kdspace::random_rays(o.random_rays, bounds, 2)}};
  const kdspace::BoxTree tree(scene.boxes);
  const kdspace::BoxTreeStats& t = tree.stats();
  std::printf(
      "\n### counts: %s, %zu boxes\n\nkdspace tree: SAH cost %.2f, %zu leaves (%zu empty), depth %zu, "
      "%.2f references per box, %.2f boxes per non-empty leaf, fullest leaf %zu.\n\n",
      scene.name.c_str(), scene.boxes.size(), t.sah_cost, t.leaves, t.empty_leaves, t.depth,
      t.references_per_box, dbl(t.references) / dbl(std::max<std::size_t>(1, t.leaves - t.empty_leaves)),
      t.max_leaf_size);
  std::vector<std::unique_ptr<EmbreeContender>> embree;
  for (const RTCBuildQuality q : o.user_qualities) {
    embree.push_back(std::make_unique<EmbreeContender>(device, false, q, o.robust));
    embree.back()->build(scene.boxes);
  }
  std::printf("| rays | count | hit %% |");
  for (const auto& e : embree) std::printf(" %s boxes / ray |", e->name().c_str());
  std::printf(
      " kdspace nodes / ray | boxes tested / ray | walk: inner nodes | leaves | empty leaves | leaves "
      "after a hit | references | distinct boxes |\n|---|---:|---:|");
  for (std::size_t e = 0; e < embree.size(); ++e) std::printf("---:|");
  std::printf("---:|---:|---:|---:|---:|---:|---:|---:|\n");
  std::vector<bool> seen(scene.boxes.size(), false);
  for (const RaySet& set : sets) {
    const double n = dbl(set.rays.size());
    std::printf("| %s | %zu |", set.name, set.rays.size());
    kdspace::RayStats stats;
    tree.closest_hit_batch(set.rays, 1, &stats);
    kdspace::bench::TreeWalkCounts walk;
    for (const Ray& r : set.rays) kdspace::bench::walk_closest_hit(tree, r, set.t_min, set.t_max, walk, seen);
    std::printf(" %.1f |", 100.0 * dbl(walk.rays_hitting) / n);
    std::string json;
    for (const auto& e : embree) {
      const std::uint64_t before = e->callbacks();
      e->trace(set, 1);
      const double per_ray = dbl(e->callbacks() - before) / n;
      std::printf(" %.2f |", per_ray);
      char field[96];
      std::snprintf(field, sizeof field, "\"%s_boxes_per_ray\":%.4f,", e->name().c_str(), per_ray);
      json += field;
    }
    std::printf(" %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f |\n", stats.nodes_visited_per_ray(),
                stats.boxes_tested_per_ray(), dbl(walk.inner_nodes) / n, dbl(walk.leaves) / n,
                dbl(walk.empty_leaves) / n, dbl(walk.leaves_after_hit) / n, dbl(walk.references) / n,
                dbl(walk.distinct_boxes) / n);
    std::printf(
        "{\"bench\":\"rays-counts\",\"scene\":\"%s\",\"boxes\":%zu,\"rays\":\"%s\",\"count\":%zu,%s"
        "\"nodes_per_ray\":%.4f,\"boxes_tested_per_ray\":%.4f,\"inner_nodes_per_ray\":%.4f,"
        "\"leaves_per_ray\":%.4f,\"empty_leaves_per_ray\":%.4f,\"leaves_after_hit_per_ray\":%.4f,"
        "\"references_per_ray\":%.4f,\"distinct_boxes_per_ray\":%.4f}\n",
        scene.name.c_str(), scene.boxes.size(), set.name, set.rays.size(), json.c_str(),
        stats.nodes_visited_per_ray(), stats.boxes_tested_per_ray(), dbl(walk.inner_nodes) / n,
        dbl(walk.leaves) / n, dbl(walk.empty_leaves) / n, dbl(walk.leaves_after_hit) / n,
        dbl(walk.references) / n, dbl(walk.distinct_boxes) / n);
  }
}

/// Runs one scene and prints its tables and JSON lines. Returns false on a real disagreement.
bool run_scene(const Options& o, const Scene& scene,
               const std::vector<std::unique_ptr<Contender>>& contenders,
               std::vector<SceneSummary>& summary) {
  const std::vector<Box3f>& boxes = scene.boxes;
  const std::size_t n = boxes.size();
  const Box3f bounds = scene_bounds(boxes);
  // Grazing threshold: 1e-5 of the scene's diagonal.
  const double graze = 1e-5 * std::sqrt(std::pow(bounds.hi[0] - bounds.lo[0], 2.0) +
                                        std::pow(bounds.hi[1] - bounds.lo[1], 2.0) +
                                        std::pow(bounds.hi[2] - bounds.lo[2], 2.0));
  std::array<RaySet, 3> sets{
      RaySet{"primary", false,
             kdspace::primary_rays(kdspace::fit_camera(bounds, dbl(o.width) / dbl(o.height)), o.width,
                                   o.height)},
      RaySet{"random", false, kdspace::random_rays(o.random_rays, bounds, 2)}, RaySet{"shadow", true, {}}};
  {
    const kdspace::BoxTree tree(boxes);
    sets[2].rays = shadow_rays(sets[0].rays, tree.closest_hit_batch(sets[0].rays), bounds);
    sets[2].t_min = shadow_t_min;
    sets[2].t_max = 1;
  }

  std::vector<Samples> samples(contenders.size());
  std::array<std::vector<Hit>, 3> reference;  // kdspace, first repetition, 1 thread
  for (int rep = 0; rep < o.reps; ++rep) {
    for (std::size_t c = 0; c < contenders.size(); ++c) {
      Contender& contender = *contenders[c];
      std::fprintf(stderr, "  %s (%zu boxes) rep %d/%d: %s\n", scene.name.c_str(), n, rep + 1, o.reps,
                   contender.name().c_str());
      const Stopwatch build;
      contender.build(boxes);
      samples[c].build_s.push_back(build.seconds());
      samples[c].memory_bytes = contender.memory_bytes();
      for (std::size_t s = 0; s < sets.size(); ++s) {
        std::array<std::vector<Hit>, 2> answers;
        for (unsigned threads = 1; threads <= 2; ++threads) {
          const Stopwatch clock(threads);
          answers[threads - 1] = contender.trace(sets[s], threads);
          const double seconds = clock.seconds();
          samples[c].mrays[s][threads - 1].push_back(dbl(sets[s].rays.size()) / seconds / 1e6);
        }
        if (rep != 0) continue;
        // c = 0 is kdspace: it sets the reference the others are compared with.
        if (c == 0) reference[s] = answers[0];
        Agreement& g = samples[c].agreement[s];
        const bool triangles = std::string(contender.library()) == "embree-tri";
        if (c != 0)
          g = compare(reference[s], answers[0], sets[s], boxes, graze, triangles && !sets[s].any_hit,
                      !triangles, contender.name() + " " + sets[s].name);
        g.threads_differ = count_different(answers[0], answers[1]);
      }
      contender.release();
    }
  }

  // The user-geometry peer: the better of the qualities run.
  std::size_t peer = 0;
  for (std::size_t c = 1; c < contenders.size(); ++c)
    if (std::string(contenders[c]->library()) == "embree-user" &&
        (peer == 0 ||
         samples[c].geometric_mean_speed(sets.size()) > samples[peer].geometric_mean_speed(sets.size())))
      peer = c;

  std::printf(
      "\n### %s: %zu boxes; %zu primary rays (%zux%zu), %zu random rays, %zu shadow rays (any hit); median "
      "of "
      "%d\n\n",
      scene.name.c_str(), n, sets[0].rays.size(), o.width, o.height, sets[1].rays.size(), sets[2].rays.size(),
      o.reps);
  std::printf(
      "| contender | build s | memory MB | primary Mrays/s 1 thr | 2 thr | random 1 thr | 2 thr | shadow 1 "
      "thr | "
      "2 thr | kdspace / contender: build s | primary 1 thr | 2 thr | random 1 thr | 2 thr | shadow 1 thr | "
      "2 "
      "thr |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  const Samples& kd = samples[0];
  for (std::size_t c = 0; c < contenders.size(); ++c) {
    const Samples& s = samples[c];
    std::string name = contenders[c]->name();
    if (c == peer && c != 0) name += " (peer)";
    std::printf("| %s | %.4f | %.1f |", name.c_str(), median(s.build_s), dbl(s.memory_bytes) / 1e6);
    for (std::size_t set = 0; set < sets.size(); ++set)
      std::printf(" %.3f | %.3f |", s.speed(set, 0), s.speed(set, 1));
    if (c == 0) {
      std::printf(" - | - | - | - | - | - | - |\n");
      continue;
    }
    std::printf(" %s |", format_ratio(median(kd.build_s), median(s.build_s)).c_str());
    for (std::size_t set = 0; set < sets.size(); ++set)
      std::printf(" %s | %s |", format_ratio(kd.speed(set, 0), s.speed(set, 0)).c_str(),
                  format_ratio(kd.speed(set, 1), s.speed(set, 1)).c_str());
    std::printf("\n");
  }
  if (peer != 0) {
    SceneSummary line;
    line.scene = scene.name;
    line.boxes = n;
    line.peer = contenders[peer]->name();
    line.build_kd = median(kd.build_s);
    line.build_peer = median(samples[peer].build_s);
    for (std::size_t set = 0; set < sets.size(); ++set) {
      line.kd[set] = kd.speed(set, 0);
      line.other[set] = samples[peer].speed(set, 0);
    }
    summary.push_back(line);
  }

  print_profile(scene, sets);

  std::printf(
      "\nAgreement with kdspace (first repetition, 1 thread). t differs: |dt| > 1e-4 max(t) + 1e-6 diagonal; "
      "near ties: other box at a close but unequal t (float rounding); ties: other box at equal t; "
      "grazing: the closer hit's path through its box (or miss) <= 1e-5 of the scene diagonal; "
      "inside: kdspace hit at t = 0, left out of the other columns for triangles; shadow rays: hit or miss "
      "only.\n\n");
  std::printf(
      "| contender | rays | compared | hit/miss | t differs | near ties | ties (equal t) | grazing | "
      "inside | 2 thr != 1 thr |\n");
  std::printf("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  bool agree = true;
  for (std::size_t c = 0; c < contenders.size(); ++c) {
    for (std::size_t set = 0; set < sets.size(); ++set) {
      const Agreement& g = samples[c].agreement[set];
      if (c == 0) {
        std::size_t inside = 0;
        for (const Hit& h : reference[set]) inside += !sets[set].any_hit && h.hit() && h.t == 0 ? 1 : 0;
        std::printf("| %s | %s | - | - | - | - | - | - | %zu | %zu |\n", contenders[c]->name().c_str(),
                    sets[set].name, inside, g.threads_differ);
      } else {
        std::printf("| %s | %s | %zu | %zu | %zu | %zu | %zu | %zu | %zu%s | %zu |\n",
                    contenders[c]->name().c_str(), sets[set].name, g.rays, g.hit_miss, g.t_differs,
                    g.near_ties, g.ties, g.grazing, g.inside, g.inside_excluded ? " (left out)" : "",
                    g.threads_differ);
      }
      const bool user = std::string(contenders[c]->library()) == "embree-user";
      if (g.threads_differ > 0 || (user && g.real() > 0)) agree = false;
    }
  }
  if (!agree)
    std::printf("\nDISAGREEMENT: see the table above (user geometry beyond ties and rounding, or threads)\n");

  std::printf("\n");
  for (std::size_t c = 0; c < contenders.size(); ++c) {
    const Samples& s = samples[c];
    for (std::size_t set = 0; set < sets.size(); ++set)
      for (int t = 0; t < 2; ++t) {
        const Agreement& g = s.agreement[set];
        std::printf(
            "{\"bench\":\"rays\",\"library\":\"%s\",\"build_quality\":\"%s\",\"boxes\":%zu,\"scene\":\"%s\","
            "\"scene_kind\":\"%s\",\"rays\":\"%s\",\"ray_count\":%zu,\"threads\":%d,\"mrays_s\":%.4f,"
            "\"build_s\":%.5f,\"memory_bytes\":%zu,\"reps\":%d",
            contenders[c]->library(), contenders[c]->quality(), n, scene.name.c_str(), scene.kind.c_str(),
            sets[set].name, sets[set].rays.size(), t + 1, s.speed(set, t), median(s.build_s), s.memory_bytes,
            o.reps);
        if (c != 0)
          std::printf(
              ",\"peer\":%s,\"hit_miss\":%zu,\"t_differs\":%zu,\"near_ties\":%zu,\"ties\":%zu,"
              "\"grazing\":%zu,\"inside\":%zu,\"inside_excluded\":%s",
              c == peer ? "true" : "false", g.hit_miss, g.t_differs, g.near_ties, g.ties, g.grazing, g.inside,
              g.inside_excluded ? "true" : "false");
        std::printf("}\n");
      }
  }
  std::fflush(stdout);
  return agree;
}

/// The summary: kdspace against the peer on every scene, 1 thread.
void print_summary(const std::vector<SceneSummary>& summary) {
  std::printf(
      "\n## Summary: kdspace against the peer (the faster Embree user geometry), 1 thread\n\n"
      "Build: kdspace s / peer s (lower is better). Speed: kdspace Mrays/s / peer Mrays/s (above 1: "
      "kdspace faster).\n\n");
  std::printf(
      "| scene | boxes | build s kdspace / peer | ratio | primary Mrays/s kdspace / peer | ratio | random "
      "Mrays/s kdspace / peer | ratio | shadow Mrays/s kdspace / peer | ratio |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const SceneSummary& s : summary) {
    std::printf("| %s | %zu | %.4f / %.4f | %s |", s.scene.c_str(), s.boxes, s.build_kd, s.build_peer,
                format_ratio(s.build_kd, s.build_peer).c_str());
    for (std::size_t set = 0; set < 3; ++set)
      std::printf(" %.2f / %.2f | %s |", s.kd[set], s.other[set],
                  format_ratio(s.kd[set], s.other[set]).c_str());
    std::printf("\n");
  }
  for (const SceneSummary& s : summary)
    std::printf(
        "{\"bench\":\"rays-summary\",\"scene\":\"%s\",\"boxes\":%zu,\"peer\":\"%s\",\"build_ratio\":%.4f,"
        "\"primary_ratio\":%.4f,\"random_ratio\":%.4f,\"shadow_ratio\":%.4f}\n",
        s.scene.c_str(), s.boxes, s.peer.c_str(), s.build_kd / s.build_peer, s.kd[0] / s.other[0],
        s.kd[1] / s.other[1], s.kd[2] / s.other[2]);
}

/// The scenes to run: the synthetic ones, then per real mesh its triangle boxes and its voxels.
std::vector<Scene> make_scenes(const Options& o) {
  std::vector<Scene> scenes;
  if (o.synthetic)
    for (const std::size_t n : o.sizes)
      for (const kdspace::SceneKind kind : o.kinds)
        scenes.push_back(Scene{kind_name(kind), kind_name(kind), kdspace::generate_boxes(n, kind, 1)});
  if (o.real_dir.empty()) return scenes;
  for (const kdspace::bench::Mesh& mesh : kdspace::bench::read_real_meshes(o.real_dir)) {
    if (mesh.triangles.empty()) continue;  // a scan: points only
    scenes.push_back(Scene{"mesh " + mesh.name, "mesh", kdspace::bench::triangle_boxes(mesh)});
    if (o.voxel_resolution > 0)
      scenes.push_back(
          Scene{"voxels " + mesh.name, "voxels", kdspace::bench::surface_voxels(mesh, o.voxel_resolution)});
  }
  return scenes;
}

}  // namespace

int main(int argc, char** argv) {
  const Options o = parse(argc, argv);
  use_cpu_time = o.cpu_time;
  std::vector<Scene> scenes;
  try {
    scenes = make_scenes(o);
  } catch (const kdspace::Error& e) {
    std::fprintf(stderr, "kdspace-rays-bench: %s\n", e.what());
    return 1;
  }

  // One thread for Embree's builds, like kdspace's default build.
  RTCDevice device = rtcNewDevice("threads=1");
  if (!device) {
    std::fprintf(stderr, "kdspace-rays-bench: rtcNewDevice failed (error %d)\n",
                 static_cast<int>(rtcGetDeviceError(nullptr)));
    return 1;
  }
  rtcSetDeviceErrorFunction(device, report_embree_error, nullptr);
  rtcSetDeviceMemoryMonitorFunction(device, count_embree_bytes, nullptr);

  const ssize_t tasking = rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_TASKING_SYSTEM);
  std::printf("# kdspace-rays-bench: kdspace BoxTree vs Embree %zd.%zd.%zd\n\n",
              rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_VERSION_MAJOR),
              rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_VERSION_MINOR),
              rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_VERSION_PATCH));
  std::printf(
      "kdspace: BoxTree default build (sah_nlogn, 1 thread), closest_hit_batch and any_hit_batch (packets of "
      "8 coherent rays with AVX2, else 4; the other rays in streams, one a direction octant). Embree: "
      "device \"threads=1\" (builds on 1 thread; tasking %s; backface culling %s), rtcIntersect1 / "
      "rtcOccluded1 "
      "per ray; user geometry = boxes with kdspace's slab test in the callbacks; tri = 12 triangles per box. "
      "Build quality in the name. 2 thr: two threads sharing the rays in chunks of 256. hardware threads: "
      "%u. "
      "Times: %s.\n",
      tasking == 0   ? "internal"
      : tasking == 1 ? "TBB"
      : tasking == 2 ? "PPL"
                     : "unknown",
      rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED) ? "on" : "off",
      std::thread::hardware_concurrency(),
      o.cpu_time ? "CPU seconds of the process / threads at work (--cpu-time)" : "wall seconds");

  bool agree = true;
  {
    std::vector<std::unique_ptr<Contender>> contenders;
    contenders.push_back(std::make_unique<KdspaceContender>());
    for (const RTCBuildQuality q : o.user_qualities)
      contenders.push_back(std::make_unique<EmbreeContender>(device, false, q, o.robust));
    for (const RTCBuildQuality q : o.triangle_qualities)
      contenders.push_back(std::make_unique<EmbreeContender>(device, true, q, o.robust));
    if (o.counts) {
      for (const Scene& scene : scenes) print_counts(o, scene, device);
      rtcReleaseDevice(device);
      return 0;
    }
    std::vector<SceneSummary> summary;
    for (const Scene& scene : scenes)
      if (!run_scene(o, scene, contenders, summary)) agree = false;
    print_summary(summary);
  }
  rtcReleaseDevice(device);
  return agree ? 0 : 1;
}
