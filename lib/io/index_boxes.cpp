// Index files of the BoxTree. Sections: params (the BoxBuildParams and the depth cap the build ran
// with), boxes, nodes, references (padded as detail::lay_out pads them), leaf blocks.
//
// The leaf blocks are stored, not recomputed on load: a mapped tree then reads them from the
// mapping, and the load makes no copy of the references' boxes (24 bytes per reference, the
// largest array of the tree). The BoxTree(parts) check compares every block lane with the box its
// reference names, so a stored block can never disagree with the boxes.
#include <string>
#include <vector>

#include "kdspace/error.hpp"
#include "kdspace/io/index.hpp"

namespace kdspace::io {
namespace {

/// The box tree's node array is stored as the tree keeps it. Layout 2: BoxNode = {uint32 word;
/// uint32 info} (see box_tree.hpp), a leaf's first() a multiple of 4 in references padded to a
/// multiple of 4, with leaf blocks beside them (layout 1: unpadded references and leaf boxes).
constexpr std::uint32_t box_node_layout = 2;
static_assert(sizeof(BoxNode) == 8 && sizeof(Box3f) == 24 && sizeof(LeafBlock) == 96 &&
                  alignof(LeafBlock) == 32,
              "BoxNode, Box3f or LeafBlock changed: update box_node_layout");
static_assert(alignof(LeafBlock) <= index_section_alignment, "sections are not aligned for LeafBlock");

/// Version 2 of the params section: binning_threshold and threads added.
constexpr std::uint32_t box_params_version = 2;
constexpr std::size_t box_param_words = 12;

std::uint64_t float_word(float v) {
  return word_of(static_cast<double>(v));
}

}  // namespace

void save(const std::string& path, const BoxTree& tree) {
  const BoxTreeParts p = tree.parts();
  const BoxBuildParams& b = p.params;
  IndexWriter w(IndexKind::box_tree, ScalarType::float32, MetricId::none, 3, p.boxes.size());
  w.add_words(SectionType::params, 0, box_params_version,
              {static_cast<std::uint64_t>(b.method), static_cast<std::uint64_t>(b.median_position),
               float_word(b.K_t), float_word(b.K_i), float_word(b.empty_bonus), b.leaf_size, b.max_depth,
               static_cast<std::uint64_t>(b.probability), float_word(b.max_references_per_box), p.max_depth,
               b.binning_threshold, b.threads});
  w.add(SectionType::boxes, 0, 1, p.boxes.data(), p.boxes.size());
  w.add(SectionType::nodes, 0, box_node_layout, p.nodes.data(), p.nodes.size());
  w.add(SectionType::references, 0, 1, p.references.data(), p.references.size());
  w.add(SectionType::leaf_blocks, 0, 1, p.blocks.data(), p.blocks.size());
  w.add(SectionType::bounds, 0, 1, &p.bounds, 1);
  w.write(path);
}

namespace {

BoxTree box_tree_of(const std::shared_ptr<const IndexFile>& file,
                    kdspace::detail::CheckCompanion* companion) {
  const IndexInfo& info = file->info();
  if (info.kind != IndexKind::box_tree)
    file->fail("holds " + detail::with_article(name_of(info.kind)) + ", not a box tree");
  if (info.scalar != ScalarType::float32 || info.metric != MetricId::none || info.dim != 3)
    file->fail("a box tree's header must say float32, no metric, dimension 3");
  const std::vector<std::uint64_t> w =
      file->words(SectionType::params, 0, box_params_version, box_param_words);
  if (w[0] > 3 || w[1] > 1 || w[7] > 1 || w[9] > max_box_tree_depth || w[11] > 0xffffffffu)
    file->fail("box tree parameters out of range");
  BoxTreeParts p;
  BoxBuildParams& b = p.params;
  b.method = static_cast<BoxBuildMethod>(w[0]);
  b.median_position = static_cast<MedianPosition>(w[1]);
  b.K_t = static_cast<float>(double_of(w[2]));
  b.K_i = static_cast<float>(double_of(w[3]));
  b.empty_bonus = static_cast<float>(double_of(w[4]));
  b.leaf_size = static_cast<std::size_t>(w[5]);
  b.max_depth = static_cast<std::size_t>(std::min<std::uint64_t>(w[6], 1u << 20));
  b.probability = static_cast<HitProbability>(w[7]);
  b.max_references_per_box = static_cast<float>(double_of(w[8]));
  p.max_depth = static_cast<std::size_t>(w[9]);
  b.binning_threshold = static_cast<std::size_t>(std::min<std::uint64_t>(w[10], SIZE_MAX));
  b.threads = static_cast<unsigned>(w[11]);
  p.boxes = file->array<Box3f>(SectionType::boxes, 0, 1,
                               static_cast<std::size_t>(std::min<std::uint64_t>(info.count, SIZE_MAX - 1)));
  p.nodes = file->array<BoxNode>(SectionType::nodes, 0, box_node_layout);
  p.references = file->array<std::uint32_t>(SectionType::references, 0, 1);
  p.blocks = file->array<LeafBlock>(SectionType::leaf_blocks, 0, 1);
  p.bounds = file->array<Box3f>(SectionType::bounds, 0, 1, 1)[0];
  p.backing = file;
  p.companion = companion;
  try {
    return BoxTree(std::move(p));
  } catch (const Error& e) {
    file->fail(e.what());
  }
}

}  // namespace

BoxTree load_box_tree(const std::shared_ptr<const IndexFile>& file) {
  return box_tree_of(file, nullptr);
}

BoxTree load_box_tree_deferred(const std::shared_ptr<const IndexFile>& file) {
  // The check reads the references and their leaf blocks front to back, reference by reference, and
  // the boxes front to back (besides looking them up by reference).
  constexpr std::size_t block_bytes_per_reference = sizeof(LeafBlock) / 4;
  return detail::load_beside_checksums(
      *file,
      {{kdspace::detail::box_check_references, file->find(SectionType::references), sizeof(std::uint32_t)},
       {kdspace::detail::box_check_references, file->find(SectionType::leaf_blocks),
        block_bytes_per_reference},
       {kdspace::detail::box_check_boxes, file->find(SectionType::boxes), sizeof(Box3f)}},
      [&](kdspace::detail::CheckCompanion* checksums) { return box_tree_of(file, checksums); });
}

}  // namespace kdspace::io
