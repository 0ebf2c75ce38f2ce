// Uses the installed library: a kd-tree over one triangle, one ray; and an AFF parse error.
#include <artrace/core/kd_tree.h>
#include <artrace/io/aff_scene.h>
#include <artrace/io/parse_error.h>

#include <cstdio>

int main() {
  const artrace::core::KdTree tree({{{0, 0, 5}, {4, 0, 5}, {0, 4, 5}}});
  const artrace::core::Hit h = tree.intersect(artrace::core::Ray{{1, 1, 0}, {0, 0, 1}});
  if (!h.valid() || h.t != 5.0f) {
    std::printf("consumer: wrong hit\n");
    return 1;
  }
  try {
    artrace::io::load_aff("/nonexistent.aff");
    return 1;
  } catch (const artrace::io::ParseError& e) {
    std::printf("consumer: hit at t=%g; error as expected: %s\n", h.t, e.what());
  }
  return 0;
}
