// texstream-corrupt --scene DIR --out DIR [--seed S] [--max N] [--repeat]
// Writes a corpus of damaged texture files (corrupt_corpus.hpp) and lists each case: texture id, file,
// mutation, and which mips the server must refuse.
#include <CLI/CLI.hpp>

#include <cstdio>

#include "corrupt_corpus.hpp"

int main(int argc, char** argv) {
  CLI::App app{"texstream-corrupt: a scene copy with damaged texture files, one mutation per texture"};
  std::string scene, out;
  texstream::chaos::CorpusOptions o;
  app.add_option("--scene", scene, "source scene (texstream-gen)")->required();
  app.add_option("--out", out, "corpus folder to write")->required();
  app.add_option("--seed", o.seed, "seed of the bit flips and garbage");
  app.add_option("--max", o.max_cases, "at most this many damaged files (0: no limit)");
  app.add_flag("--repeat", o.repeat, "cycle the mutations over every texture (one damaged file per texture)");
  CLI11_PARSE(app, argc, argv);
  auto corpus = texstream::chaos::make_corrupt_corpus(scene, out, o);
  if (!corpus) {
    std::fprintf(stderr, "texstream-corrupt: %s\n", corpus.error().message.c_str());
    return 1;
  }
  for (const auto& c : corpus->cases) {
    std::printf("%u\t%s\t%s\t%s\n", c.texture, c.file.c_str(), c.mutation.c_str(),
                c.all_must_fail              ? "all mips must fail"
                : c.first_failing_mip != ~0u ? ("mips >= " + std::to_string(c.first_failing_mip) + " must fail").c_str()
                                             : "served as stored");
  }
  if (!corpus->skipped.empty()) std::fprintf(stderr, "texstream-corrupt: skipped %s\n", corpus->skipped.c_str());
  std::fprintf(stderr, "texstream-corrupt: %zu damaged files, %zu intact, in %s\n", corpus->cases.size(),
               corpus->intact.size(), out.c_str());
  return 0;
}
