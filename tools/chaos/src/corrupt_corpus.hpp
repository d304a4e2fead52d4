#pragma once
// A corpus of damaged texture files (issue 9): a copy of a scene whose DDS files are mutated one mutation per
// texture — truncation at every mip boundary (and one byte short of it), inside the header and to zero
// bytes; bit flips in the header and in the texel data; wrong header size, huge and zero dimensions, wrong
// mip counts, wrong and unknown formats, bad magic; zeroed regions; a header of another extent; trailing
// garbage; unreadable permissions; a missing file; a directory in place of the file; and, for RGBA8
// textures, the DDS replaced by a truncated mipmapped TIFF, a truncated OpenEXR, or a truncated JPEG under a
// .tif name (the other containers the server reads, through OpenImageIO). Textures past the mutations are
// copied intact (controls: they must keep streaming).
//
// Each case says what the server must answer: which mips must fail (the damage makes them unservable), and,
// for the rest, that a kOk payload must equal the (mutated) file's bytes at the texture table's byte range
// when the header is unchanged
// (a bit flip in texel data cannot be detected — DDS has no checksum — but it must be served as it is).
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "texstream/common/result.hpp"
#include "texstream/common/scene_format.hpp"

namespace texstream::chaos {

struct CorruptCase {
  uint32_t texture = 0;
  std::string mutation;              // e.g. "truncated at 640 (end of mip 1)"
  std::filesystem::path file;        // the damaged file (or where it would be)
  bool all_must_fail = false;        // no mip of it may be served
  uint32_t first_failing_mip = ~0u;  // mips >= this lie (partly) past a truncation: must fail
  bool unreadable = false;           // chmod 000 (only when that stops reads: not as root)
  // The header differs from the original: for an rgba8 texture the server may then decode the file through
  // OpenImageIO (e.g. other channel masks), so a kOk payload need not be the raw bytes.
  bool header_changed = false;
  bool other_format = false;  // not a DDS any more (TIFF, OpenEXR, JPEG): `file` has that suffix
};

struct CorpusOptions {
  uint64_t seed = 1;
  uint32_t max_cases = 0;  // 0: one texture per mutation until textures or mutations run out
  bool repeat = false;     // cycle the mutation list over every texture (10^4+ files from a big scene)
};

struct Corpus {
  std::vector<CorruptCase> cases;
  std::vector<uint32_t> intact;  // control textures, copied unchanged
  std::vector<scene::TextureRecord> table;
  std::string skipped;  // mutations that could not be made here, and why
};

// Copies `scene_dir`'s scene files into `out_dir` (created; must not be the source) and writes the damaged
// textures. The source must be a DDS scene (scene_format.hpp).
Result<Corpus> make_corrupt_corpus(const std::filesystem::path& scene_dir, const std::filesystem::path& out_dir,
                                   const CorpusOptions& options);

// True when chmod 000 stops this process from reading a file (false as root or with CAP_DAC_OVERRIDE).
bool permissions_stop_reads(const std::filesystem::path& dir);

}  // namespace texstream::chaos
