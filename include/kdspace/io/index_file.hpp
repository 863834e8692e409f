// The index file (.kdx): one binary format for every kind of index kdspace saves, read by
// memory-mapping (queries then run straight from the mapping) or into memory.
//
// Layout (all numbers little-endian; offsets from the start of the file):
//
//   offset  bytes  header
//        0      8  magic: 0x89 'K' 'D' 'X' 0x0D 0x0A 0x1A 0x0A (a byte above 127, CR LF, EOF, LF:
//                  a transfer that mangles any of them is caught at once)
//        8      4  format version: 1
//       12      4  byte order mark: 0x01020304 as the writer stores a uint32 (bytes 04 03 02 01)
//       16      4  index kind (IndexKind)
//       20      4  scalar type of the coordinates (ScalarType)
//       24      4  metric (MetricId)
//       28      4  S, the number of sections (at most max_sections)
//       32      8  dimension
//       40      8  count: points, or boxes
//       48      8  size of the whole file in bytes
//       56      4  CRC-32C of the section table
//       60      4  CRC-32C of bytes 0..59
//       64   40*S  section table, one entry a section:
//                    +0  4  section type (SectionType)
//                    +4  4  part: the tree a section belongs to, in indexes of several trees; else 0
//                    +8  4  layout version of the section's content (e.g. of a node array)
//                   +12  4  bytes of one item (a node, a coordinate, an index)
//                   +16  8  offset, a multiple of 64 (every array is aligned for its type)
//                   +24  8  length in bytes, a multiple of the item bytes
//                   +32  4  CRC-32C of the section's bytes
//                   +36  4  0 (reserved)
//   then the sections, each at its offset, zero bytes between them.
//
// Build parameters live in a `params` section of uint64 words (floating-point values as the bits
// of a double), whose meaning the index kind and the section's version fix.
//
// Opening checks, before anything is used: the magic, version, byte order, header and table
// checksums, that the file has the size its header says, that every section lies inside the file,
// aligned and apart from the others, that every byte outside the header, the table and the sections
// is zero (no byte of the file goes unchecked), and every section's checksum. The loaders of each
// kind then check the sections they need and the structure they hold (tree links in range, leaf
// ranges in range, no cycles, and for point trees every point inside the splits above it) before a
// query can run, while a second thread checks the sections' checksums in chunks that the first shares
// once done (structural checks are safe on any bytes); both pass, or no index. A large point tree's
// check runs on threads of its own (as many as the loader is given), a box tree's on two, reading
// the arrays it reads in pieces, each front to back (a point tree's nodes, points and order, a
// subtree at a time, whichever thread is free taking the next; a box tree's boxes, references and
// leaf blocks, a half a thread), which it checksums just before it checks them (SectionChecksums:
// each byte read from memory once); then its threads share the other sections' chunks. Every problem
// throws kdspace::Error naming the file and what is wrong; nothing is allocated for what a header
// claims (every length is checked against the file's size first).
//
// Saving is atomic: the file is written under a temporary name in the same folder, flushed to disk
// (fsync), renamed over the target, and the folder is flushed. A crash or a full disk mid-save
// leaves the old file as it was (and may leave a stray PATH.tmp.* file, never a damaged PATH).
//
// Adding an index kind: one IndexKind value, its SectionType values (numbers not used before), a
// writer that adds its sections to an IndexWriter, and a loader that takes them from an IndexFile
// and checks them. Nothing else in this file changes.
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <memory>
#include <string>
#include <vector>

#include "kdspace/detail/check_companion.hpp"
#include "kdspace/detail/storage.hpp"

namespace kdspace::detail {
class SectionThread;  // detail/section_thread.hpp: PendingChecksums' thread, in index_file.cpp alone
}

namespace kdspace::io {

inline constexpr std::uint32_t index_format_version = 1;
inline constexpr std::size_t index_header_bytes = 64;
inline constexpr std::size_t index_section_entry_bytes = 40;
inline constexpr std::size_t index_section_alignment = 64;
inline constexpr std::uint32_t max_sections = 4096;

enum class IndexKind : std::uint32_t {
  point_tree = 1,          ///< PointTree
  dynamic_point_tree = 2,  ///< DynamicPointTree: several point trees, their ids and removals
  point_forest = 3,        ///< PointForest
  box_tree = 4,            ///< BoxTree
};

enum class ScalarType : std::uint32_t { none = 0, float32 = 1, float64 = 2 };
/// The metric of a point index; Minkowski's order p is in the params section.
enum class MetricId : std::uint32_t { none = 0, l2 = 1, l1 = 2, linf = 3, minkowski = 4 };

enum class SectionType : std::uint32_t {
  params = 1,         ///< uint64 words: build parameters (and for a forest its derived figures)
  nodes = 2,          ///< a tree's node array, as the tree keeps it in memory
  points = 3,         ///< coordinates (float32 or float64) in the order the index keeps them
  point_bytes = 4,    ///< coordinates as bytes (a forest over byte-valued data)
  order = 5,          ///< uint32 per point: original index (point tree) or row (forest tree)
  ids = 6,            ///< uint32 per point: its id (DynamicPointTree part) or original index (forest)
  removed = 7,        ///< uint32: the removed points of a tree of a DynamicPointTree (its rows)
  dynamic_state = 8,  ///< uint64 words: next id, base capacity, trees, each tree's level, buffered points
  mean = 9,           ///< float64 per axis (forest)
  projection = 10,    ///< float64, dim x projected dims (forest)
  boxes = 11,         ///< 6 float32 per box (box tree)
  references = 12,    ///< uint32 per leaf entry: box index (box tree)
  leaf_boxes = 13,    ///< box trees of node layout 1 only (no longer read or written)
  bounds = 14,        ///< coordinates: the lower corner of the bounds of all points, then the upper
  leaf_blocks = 15,   ///< LeafBlocks: the references' boxes, 4 per block, per coordinate (box tree)
  graph = 16,         ///< uint32, points x degree: each row's neighbour list (forest)
};

enum class LoadMode {
  map,   ///< memory-map the file: the index reads its arrays from the mapping, nothing is copied
  read,  ///< read the file into memory first (then the file may change or go)
};

/// When IndexFile::open checks the sections' checksums.
enum class Checksums {
  now,       ///< before it returns
  deferred,  ///< when verify_checksums() is called (the loaders run it beside their structural checks)
};

/// Names for messages: "point tree", "nodes", "float32", "l2".
const char* name_of(IndexKind kind);
const char* name_of(SectionType type);
const char* name_of(ScalarType type);
const char* name_of(MetricId metric);

struct SectionEntry {
  SectionType type;
  std::uint32_t part = 0;
  std::uint32_t version = 1;
  std::uint32_t item_bytes = 1;
  std::uint64_t offset = 0;
  std::uint64_t length = 0;
  std::uint32_t crc = 0;
};

/// The header of an index file, and its section table.
struct IndexInfo {
  IndexKind kind = IndexKind::point_tree;
  ScalarType scalar = ScalarType::none;
  MetricId metric = MetricId::none;
  std::uint64_t dim = 0;
  std::uint64_t count = 0;
  std::uint64_t file_bytes = 0;
  std::vector<SectionEntry> sections;
};

/// An index file, opened and checked (see the top of this file). The arrays it hands out are read
/// straight from the mapping (or the buffer it was read into), so an index built on them keeps the
/// IndexFile alive (a shared_ptr) as long as it lives.
class IndexFile {
 public:
  /// Opens `path` and checks it; throws Error("PATH: what is wrong"). With Checksums::deferred
  /// everything but the sections' checksums is checked.
  static std::shared_ptr<const IndexFile> open(const std::string& path, LoadMode mode = LoadMode::map,
                                               Checksums checksums = Checksums::now);
  /// Checks a copy of bytes already in memory (`name` stands for the file in messages): the fuzz
  /// targets' way in.
  static std::shared_ptr<const IndexFile> from_bytes(const unsigned char* bytes, std::size_t size,
                                                     const std::string& name);
  ~IndexFile();
  IndexFile(const IndexFile&) = delete;
  IndexFile& operator=(const IndexFile&) = delete;

  const std::string& path() const { return path_; }
  const IndexInfo& info() const { return info_; }
  /// Whether the file was memory-mapped.
  bool mapped() const { return mapped_; }

  /// The section of that type and part, or null.
  const SectionEntry* find(SectionType type, std::uint32_t part = 0) const;

  /// The section as an array of V, borrowed from the file. Throws Error when it is missing, when its
  /// layout version is not `version`, when its items are not sizeof(V) bytes, or when `count` (if
  /// not `any_count`) differs from its number of items.
  static constexpr std::size_t any_count = static_cast<std::size_t>(-1);
  template <class V>
  kdspace::detail::Storage<V> array(SectionType type, std::uint32_t part, std::uint32_t version,
                                    std::size_t count = any_count) const {
    const SectionEntry& s = section(type, part, version, sizeof(V), count);
    return kdspace::detail::Storage<V>::borrow(reinterpret_cast<const V*>(bytes_ + s.offset),
                                               static_cast<std::size_t>(s.length / sizeof(V)));
  }
  /// A params or state section: its uint64 words, at least `min_words` of them.
  std::vector<std::uint64_t> words(SectionType type, std::uint32_t part, std::uint32_t version,
                                   std::size_t min_words) const;

  /// Checks every section's checksum (for a file opened with Checksums::deferred); thread-safe.
  void verify_checksums() const;

  /// The sections' checksums as chunks of a fixed size that several threads share: each calls run(),
  /// which takes chunks until none is left; once all have returned, finish() combines each section's
  /// chunk checksums (crc32c_combine) and throws Error naming the first damaged section (it checksums
  /// itself whatever is left, so that it always judges every byte).
  ///
  /// Some sections may be `streamed` instead (a null entry stands for a section the file lacks: its
  /// stream does nothing): left out of the shared chunks, each is checksummed by the threads that read
  /// it anyway (a point tree's walks over its nodes, points and order), in the pieces they read it in
  /// (pieces() sets them; one stream a piece, used by one thread at a time), as they go (stream(k,
  /// piece, end): the bytes up to `end` of streamed section k are about to be read), so that each byte
  /// is read from memory once. finish() checksums whatever of a section the streams did not reach, so
  /// its result never depends on how far they got.
  class ChecksumPass {
   public:
    explicit ChecksumPass(const IndexFile& file, std::vector<const SectionEntry*> streamed = {});
    /// Returns how many chunks this call took.
    std::size_t run();
    /// Streamed section k in pieces: piece p is bytes [starts[p], starts[p + 1]), the last one up to
    /// the section's end (the first begins at 0 whatever starts[0]; starts are clamped to ascend
    /// within the section). Until then a section is one piece.
    void pieces(std::size_t k, const std::vector<std::uint64_t>& starts);
    /// The stream of piece `piece` of streamed section k checksums its range up to byte `end` of the
    /// section, and a little beyond (a step at a time, within its range). Returns the byte it has now
    /// reached (the end of its range once done).
    std::uint64_t stream(std::size_t k, std::size_t piece, std::uint64_t end);
    void finish();

   private:
    struct Chunk {
      std::size_t section;
      std::uint64_t offset, length;
    };
    // A range [begin, end) of a streamed section's bytes, checksummed up to `done`; a cache line of its
    // own (two threads stream neighbouring pieces).
    struct alignas(64) Stream {
      std::uint64_t begin = 0, done = 0, end = 0;
      std::uint32_t crc = 0;
    };
    struct Streamed {
      const SectionEntry* section;
      std::vector<Stream> streams;
    };
    const IndexFile& file_;
    std::vector<Chunk> chunks_;
    std::vector<std::uint32_t> crcs_;
    std::atomic<std::size_t> next_{0};
    std::vector<Streamed> streamed_;
  };

  /// Throws Error("PATH: what").
  [[noreturn]] void fail(const std::string& what) const;
  /// "section 3 (nodes of part 0)", for messages.
  std::string describe(const SectionEntry& s) const;

 private:
  IndexFile() = default;
  void check(Checksums checksums);
  const SectionEntry& section(SectionType type, std::uint32_t part, std::uint32_t version,
                              std::size_t item_bytes, std::size_t count) const;

  std::string path_;
  IndexInfo info_;
  const unsigned char* bytes_ = nullptr;
  std::size_t size_ = 0;
  bool mapped_ = false;
  void* buffer_ = nullptr;  // LoadMode::read: the aligned copy of the file
};

/// The checksums of a file, taken beside the structural check of the tree loaded from it (a
/// CheckCompanion): the sections the check reads front to back (its `readers`) by the pieces they are
/// read in, each range just before it is read, and the others in chunks, by whichever thread is done
/// first. finish() throws Error naming the first damaged section.
class SectionChecksums final : public kdspace::detail::CheckCompanion {
 public:
  /// Item i of the check's array `array` is bytes [i * item_bytes, (i + 1) * item_bytes) of
  /// `section` (null: a section the file lacks, left to the loader to name).
  struct Reader {
    std::size_t array;
    const SectionEntry* section;
    std::size_t item_bytes;
  };
  SectionChecksums(const IndexFile& file, const std::vector<Reader>& readers);
  void pieces(std::size_t array, const std::vector<std::size_t>& starts) override;
  std::size_t ready(std::size_t array, std::size_t piece, std::size_t end) override;
  void help() override { pass_.run(); }
  void finish() { pass_.finish(); }

 private:
  static std::vector<const SectionEntry*> sections_of(const std::vector<Reader>& readers);
  std::vector<Reader> readers_;
  IndexFile::ChecksumPass pass_;
};

/// The checksums of a file, left running when the load of an index from it returns: taken on a
/// thread of their own once the index's structural check is done, so that the index answers queries
/// while they run. Its check (Verify::safety) keeps every query inside the index's arrays
/// whatever the file's bytes, so such an index answers safely, but not yet surely: a damaged byte of a
/// point, say, shows only in its section's checksum. So wait() before an answer is used; the kdspace
/// command writes none before. (load_point_tree_deferred takes one.)
class PendingChecksums {
 public:
  PendingChecksums() = default;
  PendingChecksums(const PendingChecksums&) = delete;
  PendingChecksums& operator=(const PendingChecksums&) = delete;
  /// Waits for the thread, if one runs; judges nothing.
  ~PendingChecksums();

  /// Starts taking every section's checksum of `file` (opened with Checksums::deferred): on a thread
  /// of its own when `own_thread` (if one can be had), else all in wait(). Once only.
  void start(const std::shared_ptr<const IndexFile>& file, bool own_thread);
  bool started() const { return pass_ != nullptr; }
  /// Waits until the checksums are all taken (taking a share of what is left itself), then throws
  /// Error("PATH: section ...: checksum mismatch: the file is damaged") for the first damaged section,
  /// again on every later call. Returns at once when nothing was started.
  void wait();
  /// When the last checksum was taken (after wait(); the epoch when nothing was started).
  std::chrono::steady_clock::time_point done_at() const { return done_at_; }

 private:
  std::shared_ptr<const IndexFile> file_;
  std::unique_ptr<IndexFile::ChecksumPass> pass_;
  std::unique_ptr<kdspace::detail::SectionThread> thread_;
  std::chrono::steady_clock::time_point done_at_{}, thread_done_at_{};
  std::exception_ptr error_;
  bool waited_ = false;
};

/// Collects the sections of one index and writes them as one file, atomically.
class IndexWriter {
 public:
  IndexWriter(IndexKind kind, ScalarType scalar, MetricId metric, std::uint64_t dim, std::uint64_t count);

  /// Adds an array section. The data is read when write() runs: it must stay valid until then.
  template <class V>
  void add(SectionType type, std::uint32_t part, std::uint32_t version, const V* data, std::size_t count) {
    add_bytes(type, part, version, sizeof(V), data, count * sizeof(V));
  }
  /// Adds a section of values the writer keeps a copy of (params, state, bounds).
  template <class V>
  void add_values(SectionType type, std::uint32_t part, std::uint32_t version, const std::vector<V>& values) {
    add_bytes(type, part, version, sizeof(V), keep(values.data(), values.size() * sizeof(V)),
              values.size() * sizeof(V));
  }
  void add_words(SectionType type, std::uint32_t part, std::uint32_t version,
                 const std::vector<std::uint64_t>& words) {
    add_values(type, part, version, words);
  }

  /// Writes the file atomically (see the top of this file); throws Error("PATH: cannot save: ...").
  void write(const std::string& path) const;
  /// The bytes write() would write (for tests and fuzz seeds).
  std::vector<unsigned char> bytes() const;

 private:
  struct Pending {
    SectionEntry entry;
    const void* data;
  };
  void add_bytes(SectionType type, std::uint32_t part, std::uint32_t version, std::size_t item_bytes,
                 const void* data, std::size_t bytes);
  const void* keep(const void* data, std::size_t bytes);
  // The header and section table, with every offset and checksum filled in.
  std::vector<unsigned char> head() const;

  IndexInfo info_;
  std::vector<Pending> pending_;
  std::vector<std::unique_ptr<std::vector<unsigned char>>> kept_;
};

/// Recomputes every checksum of an index file held in memory (the sections' and the table's, then
/// the header's), so that tests and fuzzing can reach the structural checks behind them with bytes
/// that were changed on purpose. Does nothing to bytes too short or too broken to hold a table.
void reseal_index_bytes(std::vector<unsigned char>& bytes);

/// A double as the uint64 word that holds its bits, and back (for params sections).
std::uint64_t word_of(double v);
double double_of(std::uint64_t word);

}  // namespace kdspace::io
