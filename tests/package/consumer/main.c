/* The C API of the installed package (corofem/corofem.h and the version.h the build made): the
 * consumer's cantilever from JSON text, ten steps, its tip's sag. Built against the static library
 * (consumer_c) and the shared libcorofem_c (consumer_c_shared). Exit 0 only when every call
 * succeeded, the header's version is the library's and the tip went down. */
#include <corofem/corofem.h>

#include <stdio.h>
#include <string.h>

static const char* const kScene =
    "{\"bodies\": [{\"mesh\": {\"box\": {\"max\": [1, 0.1, 0.1], \"cells\": [10, 1, 1]}},\n"
    "  \"material\": {\"youngs_modulus\": 1e6},\n"
    "  \"fixed\": [{\"plane\": {\"point\": [0, 0, 0], \"normal\": [1, 0, 0]}}],\n"
    "  \"loads\": [{\"type\": \"gravity\"}]}],\n"
    " \"analysis\": {\"type\": \"dynamic\", \"steps\": 10}, \"backend\": \"reference\"}";

int main(void) {
  corofem_scene* scene = NULL;
  corofem_simulation* sim = NULL;
  double x[3 * 44], rest[3 * 44], sag = 0.0;
  size_t needed = 0, i;
  int finished = 0;
  if (strcmp(corofem_version(), COROFEM_VERSION_STRING) != 0) {
    fprintf(stderr, "the header says %s, the library %s\n", COROFEM_VERSION_STRING, corofem_version());
    return 1;
  }
  if (corofem_scene_parse(kScene, "", NULL, 0, &scene) != COROFEM_OK ||
      corofem_simulation_create(scene, NULL, &sim) != COROFEM_OK) {
    fprintf(stderr, "create: %s\n", corofem_last_error_message());
    corofem_scene_destroy(scene);
    return 1;
  }
  corofem_scene_destroy(scene);
  while (corofem_simulation_finished(sim, &finished) == COROFEM_OK && !finished)
    if (corofem_simulation_step(sim, NULL) != COROFEM_OK) break;
  if (corofem_last_status() != COROFEM_OK ||
      corofem_simulation_read_positions(sim, 0, x, sizeof x / sizeof x[0], &needed) != COROFEM_OK ||
      corofem_simulation_read_rest_positions(sim, 0, rest, sizeof rest / sizeof rest[0], &needed) != COROFEM_OK) {
    fprintf(stderr, "%s\n", corofem_last_error_message());
    corofem_simulation_destroy(sim);
    return 1;
  }
  for (i = 1; i < needed; i += 3)
    if (x[i] - rest[i] < sag) sag = x[i] - rest[i];
  corofem_simulation_destroy(sim);
  printf("corofem %s (C API): tip sag after 10 steps %.3g m\n", corofem_version(), sag);
  return sag < 0 ? 0 : 1;
}
