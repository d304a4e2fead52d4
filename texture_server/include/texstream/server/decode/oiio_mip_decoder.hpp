#pragma once
// Decodes exactly one mip level of a mipmapped image file through OpenImageIO: tiled TIFF / OpenEXR as made
// by `maketx` (.tx, .tif, .exr), and DDS encodings we cannot hand over raw. The file is read through our
// Storage (an OIIO IOProxy over StorageFile), so every byte read is counted, rate-limited and fault-injectable.
// Only the asked level is read: ImageInput::seek_subimage(0, level) + read_image of that level (for a tiled
// file, its tiles only; never the whole file — seed 000 §3.5).
//
// OpenImageIO 2.4 returns true from reads of truncated JPEG and TIFF files with wrong pixels (DESIGN.md), so a
// read succeeds only if it returned true AND has_error() is false AND the proxy saw no I/O error.
// Out of process: OpenImageIO runs in texstream-decode helpers (decode_helper_pool.hpp), started on the first
// decode; their reads come back to this process and go through `file`. A helper that crashes or hangs on a
// file fails that decode (kCorrupt / kTimeout naming the file) and is replaced on the next one.
// Thread-safe: concurrent calls use separate helpers (each decode is single-threaded: the workers bound CPU).
#include <cstdint>
#include <filesystem>
#include <span>

#include "texstream/common/result.hpp"
#include "texstream/common/texel_format.hpp"
#include "texstream/server/storage/storage.hpp"

namespace texstream::server {

struct DecodeOutcome {
  uint64_t bytes_read = 0;  // from storage, also when decoding failed (read amplification counts them)
};

// Decodes mip `level` of `file` (whose name is `path`: OpenImageIO picks the reader by its extension) into
// `out` as RGBA8 (texel_conversion.hpp). `expected` is the texture table's extent of that level: a file whose
// level differs, or has no such level, is kCorrupt. `out` must hold expected.width * expected.height * 4
// bytes. Errors: kCorrupt (bad or truncated file, wrong extent), kIo (storage failure); messages name the path.
Status decode_mip_rgba8(StorageFile& file, const std::filesystem::path& path, uint32_t level, Extent2D expected,
                        std::span<std::byte> out, DecodeOutcome& outcome);

}  // namespace texstream::server
