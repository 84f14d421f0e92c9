/* The C API (corofem/corofem.h) driven by a C99 program, as an engine's plug-in would: a clamped
 * beam from JSON text dragged by a handle frame by frame (its nodes on the target to 1e-9 m),
 * a handle at a point, pins, applied forces, gravity, a body from an in-memory mesh moved and
 * launched, the reports, and the errors of bad input (bad JSON, nodes and bodies out of range,
 * NULL pointers, small arrays), each with its code and message. Exits 1 on any failed check.
 *
 *   capi_test SCENE.json EXPECTED_VERSION     (CTest: samples/fig8_beam/fig8_beam.json, the project's version) */
#include <corofem/corofem.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int failures = 0;

#define CHECK(cond, ...)                                                         \
  do {                                                                           \
    if (!(cond)) {                                                               \
      ++failures;                                                                \
      fprintf(stderr, "%s:%d: check failed: %s: ", __FILE__, __LINE__, #cond);   \
      fprintf(stderr, __VA_ARGS__);                                              \
      fputc('\n', stderr);                                                       \
    }                                                                            \
  } while (0)

/* A call that must succeed; on failure the check says the library's message. */
#define OK(call)                                                                                   \
  do {                                                                                             \
    corofem_status ok_status_ = (call);                                                            \
    CHECK(ok_status_ == COROFEM_OK, "%s returned %s: %s", #call, corofem_status_name(ok_status_), \
          corofem_last_error_message());                                                           \
  } while (0)

/* A call that must fail with `code` and a message containing `part`. */
#define FAILS(call, code, part)                                                                            \
  do {                                                                                                     \
    corofem_status fails_status_ = (call);                                                                 \
    const char* fails_message_ = corofem_last_error_message();                                            \
    CHECK(fails_status_ == (code), "%s returned %s, not %s (%s)", #call, corofem_status_name(fails_status_), \
          corofem_status_name(code), fails_message_);                                                      \
    CHECK(corofem_last_status() == fails_status_, "corofem_last_status() disagrees with %s", #call);       \
    CHECK(strstr(fails_message_, (part)) != NULL, "%s: the message \"%s\" lacks \"%s\"", #call,             \
          fails_message_, (part));                                                                         \
  } while (0)

static const double kH = 1.0 / 60.0;

/* A 0.5 x 0.1 x 0.1 m beam (10 x 2 x 2 cells of 6 tets), E 1 MPa, clamped at x = 0, under gravity,
 * backward Euler at 60 Hz on the reference backend. */
static const char* const kBeamScene =
    "{\"name\": \"capi_beam\",\n"
    " \"bodies\": [{\"name\": \"beam\",\n"
    "   \"mesh\": {\"box\": {\"min\": [0, 0, 0], \"max\": [0.5, 0.1, 0.1], \"cells\": [10, 2, 2], \"tets_per_cell\": 6}},\n"
    "   \"material\": {\"youngs_modulus\": 1e6, \"poisson_ratio\": 0.3, \"density\": 1000},\n"
    "   \"fixed\": [{\"plane\": {\"point\": [0, 0, 0], \"normal\": [1, 0, 0]}}],\n"
    "   \"loads\": [{\"type\": \"gravity\", \"vector\": [0, -9.81, 0]}]}],\n"
    " \"analysis\": {\"type\": \"dynamic\", \"integrator\": \"backward_euler\", \"time_step\": 0.016666666666666666,\n"
    "              \"steps\": 5},\n"
    " \"solver\": {\"tolerance\": 1e-10, \"max_iterations\": 2000},\n"
    " \"backend\": \"reference\"}\n";

/* A free body whose mesh the program gives (the box is the placeholder the scene text needs). */
static const char* const kFreeScene =
    "{\"bodies\": [{\"name\": \"free\", \"mesh\": {\"box\": {}},\n"
    "   \"material\": {\"youngs_modulus\": 1e6, \"poisson_ratio\": 0.3, \"density\": 1000}}],\n"
    " \"analysis\": {\"type\": \"dynamic\", \"integrator\": \"backward_euler\", \"time_step\": 0.01, \"steps\": 10},\n"
    " \"solver\": {\"tolerance\": 1e-10, \"max_iterations\": 2000},\n"
    " \"backend\": \"reference\"}\n";

/* The nodes of body 0 with coordinate `axis` within 1e-9 of `value` (at most `capacity`). */
static size_t nodes_at(const double* x, size_t node_count, int axis, double value, uint32_t* out, size_t capacity) {
  size_t found = 0;
  size_t n;
  for (n = 0; n < node_count; ++n)
    if (fabs(x[3 * n + (size_t)axis] - value) < 1e-9 && found < capacity) out[found++] = (uint32_t)n;
  return found;
}

static double* read_positions(corofem_simulation* sim, int body, size_t* count) {
  size_t needed = 0;
  double* x;
  OK(corofem_simulation_read_positions(sim, body, NULL, 0, &needed));
  x = (double*)malloc(needed * sizeof(double));
  if (!x) exit(2);
  OK(corofem_simulation_read_positions(sim, body, x, needed, &needed));
  if (count) *count = needed;
  return x;
}

static int contains(const char* text, const char* part) { return text && strstr(text, part) != NULL; }

static void versions(const char* expected) {
  char numbers[64];
  sprintf(numbers, "%d.%d.%d", COROFEM_VERSION_MAJOR, COROFEM_VERSION_MINOR, COROFEM_VERSION_PATCH);
  CHECK(strcmp(corofem_version(), expected) == 0, "corofem_version() is %s, the project's %s", corofem_version(), expected);
  CHECK(strcmp(COROFEM_VERSION_STRING, expected) == 0, "COROFEM_VERSION_STRING is %s", COROFEM_VERSION_STRING);
  CHECK(strcmp(numbers, expected) == 0, "the version macros make %s", numbers);
  CHECK(strcmp(corofem_status_name(COROFEM_OK), "ok") == 0, "%s", corofem_status_name(COROFEM_OK));
  CHECK(strcmp(corofem_status_name(COROFEM_BAD_INPUT), "bad input") == 0, "%s", corofem_status_name(COROFEM_BAD_INPUT));
  CHECK(strcmp(corofem_status_name(COROFEM_INTERNAL), "internal error") == 0, "%s", corofem_status_name(COROFEM_INTERNAL));
  CHECK(strcmp(corofem_status_name((corofem_status)42), "unknown") == 0, "%s", corofem_status_name((corofem_status)42));
}

static void scene_errors(const char* scene_path) {
  corofem_scene* scene = NULL;
  int count = 0;
  const char* overrides[1];
  FAILS(corofem_scene_parse("{\"bodies\": [", "", NULL, 0, &scene), COROFEM_BAD_INPUT, "invalid JSON");
  CHECK(scene == NULL, "a failed parse gave a scene");
  FAILS(corofem_scene_parse("{\"bodies\": [{\"mesh\": {\"box\": {}}, \"materail\": {}}]}", "", NULL, 0, &scene),
        COROFEM_BAD_INPUT, "did you mean \"material\"");
  FAILS(corofem_scene_parse(NULL, "", NULL, 0, &scene), COROFEM_BAD_INPUT, "corofem_scene_parse: json is NULL");
  FAILS(corofem_scene_parse(kBeamScene, "", NULL, 0, NULL), COROFEM_BAD_INPUT, "scene is NULL");
  FAILS(corofem_scene_parse(kBeamScene, "", NULL, 2, &scene), COROFEM_BAD_INPUT, "overrides is NULL");
  FAILS(corofem_scene_load("no/such/scene.json", NULL, 0, &scene), COROFEM_IO_ERROR, "no/such/scene.json");
  CHECK(scene == NULL, "a failed load gave a scene");

  /* A success clears the last error. */
  OK(corofem_scene_load(scene_path, NULL, 0, &scene));
  CHECK(corofem_last_status() == COROFEM_OK && corofem_last_error_message()[0] == '\0',
        "after a success the last error is \"%s\"", corofem_last_error_message());
  OK(corofem_scene_body_count(scene, &count));
  CHECK(count == 1, "%s has %d bodies", scene_path, count);
  corofem_scene_destroy(scene);
  scene = NULL;

  /* Overrides are checked as the file is. */
  overrides[0] = "bodies.0.material.youngs_modulus=-1";
  FAILS(corofem_scene_load(scene_path, overrides, 1, &scene), COROFEM_BAD_INPUT, "youngs_modulus");
  CHECK(scene == NULL, "a failed load gave a scene");
  FAILS(corofem_scene_body_count(NULL, &count), COROFEM_BAD_INPUT, "scene is NULL");

  /* The input limits: a scene file over max_scene_bytes is refused naming the limit; raised, it loads. */
  {
    corofem_input_limits limits = corofem_default_input_limits();
    CHECK(limits.max_scene_bytes == 16u << 20, "the default max_scene_bytes is %llu",
          (unsigned long long)limits.max_scene_bytes);
    limits.max_scene_bytes = 10;
    FAILS(corofem_scene_load_with_limits(scene_path, NULL, 0, &limits, &scene), COROFEM_BAD_INPUT,
          "max_scene_bytes");
    CHECK(scene == NULL, "a failed load gave a scene");
    limits.max_scene_bytes = 1u << 20;
    OK(corofem_scene_load_with_limits(scene_path, NULL, 0, &limits, &scene));
    corofem_scene_destroy(scene);
    scene = NULL;
  }
  corofem_scene_destroy(NULL); /* nothing */
  corofem_simulation_destroy(NULL);
}

static corofem_simulation* create_beam(void) {
  corofem_scene* scene = NULL;
  corofem_simulation* sim = NULL;
  const char* devices[1] = {"reference"};
  corofem_options options = corofem_default_options();
  options.devices = devices;
  options.device_count = 1;
  OK(corofem_scene_parse(kBeamScene, NULL, NULL, 0, &scene));
  OK(corofem_scene_set_step_count(scene, 0)); /* open-ended: a frame loop */
  OK(corofem_simulation_create(scene, &options, &sim));
  corofem_scene_destroy(scene); /* the simulation keeps its copy */
  if (!sim) {
    fprintf(stderr, "cannot go on without the beam\n");
    exit(1);
  }
  return sim;
}

/* A handle on the tip, lifted 5 cm over 10 frames and held for 10: the tip's nodes sit on the
 * target to 1e-9 m every frame, and the beam bends up. */
static void drag_tip(void) {
  corofem_simulation* sim = create_beam();
  size_t count = 0, node_count = 0, tip_count, i;
  int bodies = 0, steps = -1, finished = -1, handle = 0, frame, a, body = -1;
  uint32_t tip[64];
  double* rest;
  double time = 0.0;
  corofem_step_report report;

  OK(corofem_simulation_body_count(sim, &bodies));
  CHECK(bodies == 1, "%d bodies", bodies);
  OK(corofem_simulation_find_body(sim, "beam", &body));
  CHECK(body == 0, "body \"beam\" is %d", body);
  FAILS(corofem_simulation_find_body(sim, "bean", &body), COROFEM_BAD_INPUT, "no body is named \"bean\"");
  OK(corofem_simulation_node_count(sim, 0, &node_count));
  CHECK(node_count == 11 * 3 * 3, "%zu nodes", node_count);
  OK(corofem_simulation_element_count(sim, 0, &count));
  CHECK(count == 10 * 2 * 2 * 6, "%zu elements", count);
  OK(corofem_simulation_step_count(sim, &steps));
  CHECK(steps == 0, "step count %d after corofem_scene_set_step_count(0)", steps);

  rest = read_positions(sim, 0, &count);
  CHECK(count == 3 * node_count, "%zu positions", count);
  tip_count = nodes_at(rest, node_count, 0, 0.5, tip, 64);
  CHECK(tip_count == 9, "%zu tip nodes", tip_count);
  OK(corofem_simulation_add_handle_nodes(sim, 0, tip, tip_count, &handle));
  CHECK(handle > 0, "handle id %d", handle);

  for (frame = 1; frame <= 20; ++frame) {
    const double lift = 0.05 * (frame < 10 ? frame / 10.0 : 1.0);
    const double target[3] = {0.5, 0.05 + lift, 0.05}; /* where the tip's centroid goes */
    double* x;
    OK(corofem_simulation_move_handle(sim, handle, target, NULL));
    memset(&report, 0, sizeof report);
    OK(corofem_simulation_step_dt(sim, kH, &report));
    CHECK(report.step == frame, "frame %d: report.step %d", frame, report.step);
    CHECK(fabs(report.time - frame * kH) < 1e-12, "frame %d: report.time %.17g", frame, report.time);
    CHECK(report.converged == 1 && report.newton_iterations >= 1 && report.linear_iterations >= 1 &&
              report.wall_seconds >= 0.0 && report.linear_residual < 1e-8,
          "frame %d: converged %d, %d Newton and %d linear iterations, linear residual %g", frame, report.converged,
          report.newton_iterations, report.linear_iterations, report.linear_residual);
    x = read_positions(sim, 0, NULL);
    for (i = 0; i < tip_count; ++i)
      for (a = 0; a < 3; ++a) {
        const size_t d = 3 * tip[i] + (size_t)a;
        const double expected = rest[d] + (a == 1 ? lift : 0.0);
        CHECK(fabs(x[d] - expected) <= 1e-9, "frame %d, node %u, axis %d: %.12f, not %.12f", frame, tip[i], a, x[d],
              expected);
      }
    if (frame == 20) {
      uint32_t middle[16];
      const size_t m = nodes_at(rest, node_count, 0, 0.25, middle, 16);
      double rise = 0.0;
      for (i = 0; i < m; ++i) rise += (x[3 * middle[i] + 1] - rest[3 * middle[i] + 1]) / (double)m;
      CHECK(m == 9 && rise > 0.005, "the beam's middle rose %.6f m with the tip held 5 cm up", rise);
      printf("capi_test: the tip held 5 cm up for 10 frames, the beam's middle rose %.4f m\n", rise);
    }
    free(x);
  }
  OK(corofem_simulation_steps_taken(sim, &steps));
  CHECK(steps == 20, "%d steps taken", steps);
  OK(corofem_simulation_time(sim, &time));
  CHECK(fabs(time - 20 * kH) < 1e-12, "time %.17g", time);
  OK(corofem_simulation_finished(sim, &finished));
  CHECK(finished == 0, "an open-ended analysis finished");
  free(rest);
  corofem_simulation_destroy(sim);
}

/* A handle at a point (the node nearest it), pins that hold, forces that push, gravity. */
static void hold_and_push(void) {
  corofem_simulation* sim = create_beam();
  corofem_simulation* still = create_beam();
  size_t node_count = 0, i, tip_count;
  uint32_t tip[16];
  int handle = 0, frame, a;
  double *rest = NULL, *pinned = NULL, *x = NULL, *y = NULL;
  const double point[3] = {0.25, 0.05, 0.05};
  const double zero[3] = {0.0, 0.0, 0.0};
  double target[3];
  corofem_force forces[2];

  OK(corofem_simulation_node_count(sim, 0, &node_count));
  rest = read_positions(sim, 0, NULL);
  tip_count = nodes_at(rest, node_count, 0, 0.5, tip, 16);

  /* The node at (0.25, 0.05, 0.05), grabbed through a point and a radius of 1 mm, moved 1 cm in z. */
  OK(corofem_simulation_add_handle_point(sim, 0, point, 1e-3, &handle));
  CHECK(handle > 0, "handle id %d", handle);
  target[0] = 0.25;
  target[1] = 0.05;
  target[2] = 0.06;
  OK(corofem_simulation_move_handle(sim, handle, target, NULL));
  OK(corofem_simulation_step_dt(sim, kH, NULL));
  x = read_positions(sim, 0, NULL);
  for (i = 0; i < node_count; ++i)
    if (fabs(rest[3 * i] - 0.25) < 1e-9 && fabs(rest[3 * i + 1] - 0.05) < 1e-9 && fabs(rest[3 * i + 2] - 0.05) < 1e-9)
      for (a = 0; a < 3; ++a)
        CHECK(fabs(x[3 * i + (size_t)a] - target[a]) <= 1e-9, "the point handle's node %zu, axis %d: %.12f", i, a,
              x[3 * i + (size_t)a]);
  free(x);
  /* Made a spring of 500 N/m, the handle no longer holds the node on the target exactly. */
  OK(corofem_simulation_set_handle_stiffness(sim, handle, 500.0));
  FAILS(corofem_simulation_set_handle_stiffness(sim, handle, -1.0), COROFEM_BAD_INPUT, "stiffness");
  OK(corofem_simulation_step_dt(sim, kH, NULL));
  OK(corofem_simulation_remove_handle(sim, handle));
  FAILS(corofem_simulation_remove_handle(sim, handle), COROFEM_BAD_INPUT, "no handle");

  /* Pinned where they are, the tip's nodes stay put under gravity; unpinned, the tip falls. */
  OK(corofem_simulation_pin_nodes(sim, 0, tip, tip_count));
  pinned = read_positions(sim, 0, NULL);
  for (frame = 0; frame < 10; ++frame) OK(corofem_simulation_step_dt(sim, kH, NULL));
  x = read_positions(sim, 0, NULL);
  for (i = 0; i < tip_count; ++i)
    for (a = 0; a < 3; ++a) {
      const size_t d = 3 * tip[i] + (size_t)a;
      CHECK(fabs(x[d] - pinned[d]) <= 1e-12, "pinned node %u moved %.3g m on axis %d", tip[i], x[d] - pinned[d], a);
    }
  free(x);
  OK(corofem_simulation_unpin_nodes(sim, 0, tip, tip_count));
  for (frame = 0; frame < 10; ++frame) OK(corofem_simulation_step_dt(sim, kH, NULL));
  x = read_positions(sim, 0, NULL);
  CHECK(x[3 * tip[0] + 1] < pinned[3 * tip[0] + 1] - 1e-3, "the unpinned tip did not fall: y %.6f, pinned at %.6f",
        x[3 * tip[0] + 1], pinned[3 * tip[0] + 1]);
  free(x);

  /* Back at rest, then without gravity the clamped beam stays exactly at rest; 2 N up at the tip
   * (one at a node, one at a point in the tip's last cell) lifts it against an untouched twin. */
  OK(corofem_simulation_reset_body(sim, 0));
  x = read_positions(sim, 0, NULL);
  CHECK(memcmp(x, rest, 3 * node_count * sizeof(double)) == 0, "reset_body did not put the body back at rest");
  free(x);
  OK(corofem_simulation_set_gravity(sim, zero));
  OK(corofem_simulation_set_gravity(still, zero));
  for (frame = 0; frame < 5; ++frame) OK(corofem_simulation_step_dt(still, kH, NULL));
  x = read_positions(still, 0, NULL);
  for (i = 0; i < 3 * node_count; ++i)
    CHECK(fabs(x[i] - rest[i]) <= 1e-12, "without gravity or forces, coordinate %zu moved %.3g m", i, x[i] - rest[i]);
  free(x);
  memset(forces, 0, sizeof forces);
  forces[0].node = (int)tip[0];
  forces[0].force[1] = 1.0;
  forces[1].node = -1;
  forces[1].point[0] = 0.49;
  forces[1].point[1] = 0.05;
  forces[1].point[2] = 0.05;
  forces[1].force[1] = 1.0;
  OK(corofem_simulation_set_forces(sim, 0, forces, 2));
  for (frame = 0; frame < 5; ++frame) OK(corofem_simulation_step_dt(sim, kH, NULL));
  x = read_positions(sim, 0, NULL);
  y = read_positions(still, 0, NULL);
  CHECK(x[3 * tip[0] + 1] - y[3 * tip[0] + 1] > 1e-3, "2 N up at the tip lifted it %.3g m in 5 frames",
        x[3 * tip[0] + 1] - y[3 * tip[0] + 1]);
  printf("capi_test: 2 N up at the tip lifted it %.4f m in 5 frames\n", x[3 * tip[0] + 1] - y[3 * tip[0] + 1]);
  free(x);
  free(y);
  OK(corofem_simulation_set_forces(sim, 0, NULL, 0)); /* removed */

  /* Bad input: each refused with its code and a message naming what is wrong. */
  forces[0].node = 5000;
  FAILS(corofem_simulation_set_forces(sim, 0, forces, 1), COROFEM_BAD_INPUT, "node 5000 is not a node");
  FAILS(corofem_simulation_set_forces(sim, 0, NULL, 1), COROFEM_BAD_INPUT, "forces is NULL");
  tip[0] = 9999;
  FAILS(corofem_simulation_add_handle_nodes(sim, 0, tip, 1, &handle), COROFEM_BAD_INPUT, "node 9999 is not a node");
  FAILS(corofem_simulation_pin_nodes(sim, 0, tip, 1), COROFEM_BAD_INPUT, "node 9999");
  FAILS(corofem_simulation_add_handle_nodes(sim, 0, tip, 0, &handle), COROFEM_BAD_INPUT, "at least one node");
  FAILS(corofem_simulation_add_handle_nodes(sim, 3, tip, 1, &handle), COROFEM_BAD_INPUT, "body index 3");
  FAILS(corofem_simulation_node_count(sim, -1, &node_count), COROFEM_BAD_INPUT, "body index -1 is out of range");
  FAILS(corofem_simulation_pin_nodes(sim, 0, NULL, 2), COROFEM_BAD_INPUT, "nodes is NULL");
  FAILS(corofem_simulation_move_handle(sim, 777, target, NULL), COROFEM_BAD_INPUT, "no handle 777");
  FAILS(corofem_simulation_step_dt(sim, -0.01, NULL), COROFEM_BAD_INPUT, "time step");
  FAILS(corofem_simulation_step_dt(NULL, kH, NULL), COROFEM_BAD_INPUT, "corofem_simulation_step_dt: simulation is NULL");
  FAILS(corofem_simulation_set_positions(sim, 0, rest, 6), COROFEM_BAD_INPUT, "positions and velocities");
  FAILS(corofem_simulation_set_gravity(sim, NULL), COROFEM_BAD_INPUT, "gravity is NULL");
  FAILS(corofem_simulation_teleport(sim, 0, NULL, zero), COROFEM_BAD_INPUT, "held by the scene");
  {
    const double stretch[9] = {2, 0, 0, 0, 1, 0, 0, 0, 1};
    OK(corofem_simulation_add_handle_nodes(sim, 0, &tip[1], 1, &handle));
    FAILS(corofem_simulation_move_handle(sim, handle, target, stretch), COROFEM_BAD_INPUT, "rotation");
  }
  {
    size_t needed = 0;
    double small[3];
    FAILS(corofem_simulation_read_positions(sim, 0, small, 3, &needed), COROFEM_BAD_INPUT, "are needed");
    CHECK(needed == 3 * node_count, "needed %zu after a small array", needed);
    FAILS(corofem_simulation_read_positions(sim, 0, NULL, 5, &needed), COROFEM_BAD_INPUT, "NULL with capacity 5");
  }
  free(rest);
  free(pinned);
  corofem_simulation_destroy(still);
  corofem_simulation_destroy(sim);
}

/* A 0.4 x 0.1 x 0.1 m box of 4 cells, 6 tetrahedra each (Kuhn's split along the cell's diagonal,
 * conforming between cells), given from memory: moved rigidly, launched, reset. */
static void memory_mesh(void) {
  enum { kCells = 4, kNodes = (kCells + 1) * 4, kTets = 6 * kCells };
  static const int kPerm[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  double nodes[3 * kNodes];
  uint32_t tets[4 * kTets], bad[4 * kTets];
  corofem_scene* scene = NULL;
  corofem_simulation* sim = NULL;
  size_t count = 0, i, needed = 0;
  int c, k, a;
  double x[3 * kNodes];
  uint32_t read_tets[4 * kTets];
  const double zero[3] = {0.0, 0.0, 0.0};
  const double move[3] = {1.0, 2.0, 3.0};
  double v[3 * kNodes];

  for (c = 0; c <= kCells; ++c)
    for (k = 0; k < 4; ++k) { /* node (c, j, l) = 4 c + 2 l + j */
      nodes[3 * (4 * c + k)] = 0.1 * c;
      nodes[3 * (4 * c + k) + 1] = 0.1 * (k & 1);
      nodes[3 * (4 * c + k) + 2] = 0.1 * (k >> 1);
    }
  for (c = 0; c < kCells; ++c)
    for (k = 0; k < 6; ++k) { /* the corners 0, e_a, e_a + e_b, e_a + e_b + e_c of the cell */
      int bits[3] = {0, 0, 0}, corner;
      uint32_t* t = &tets[4 * (6 * c + k)];
      for (corner = 0; corner < 4; ++corner) {
        if (corner > 0) bits[kPerm[k][corner - 1]] = 1;
        t[corner] = (uint32_t)(4 * (c + bits[0]) + bits[1] + 2 * bits[2]);
      }
    }
  OK(corofem_scene_parse(kFreeScene, "", NULL, 0, &scene));
  FAILS(corofem_scene_set_body_mesh(scene, 1, nodes, kNodes, tets, kTets), COROFEM_BAD_INPUT, "body index 1");
  FAILS(corofem_scene_set_body_mesh(scene, 0, NULL, kNodes, tets, kTets), COROFEM_BAD_INPUT, "nodes is NULL");

  /* A tetrahedron naming a node past the end is refused when the simulation is made. */
  memcpy(bad, tets, sizeof bad);
  bad[4 * 7 + 2] = 99;
  OK(corofem_scene_set_body_mesh(scene, 0, nodes, kNodes, bad, kTets));
  FAILS(corofem_simulation_create(scene, NULL, &sim), COROFEM_BAD_INPUT, "element 7 names node 99");
  CHECK(sim == NULL, "a failed create gave a simulation");

  OK(corofem_scene_set_body_mesh(scene, 0, nodes, kNodes, tets, kTets));
  OK(corofem_scene_set_step_count(scene, 0));
  OK(corofem_simulation_create(scene, NULL, &sim));
  corofem_scene_destroy(scene);
  if (!sim) return;
  OK(corofem_simulation_node_count(sim, 0, &count));
  CHECK(count == kNodes, "%zu nodes from memory", count);
  OK(corofem_simulation_read_rest_positions(sim, 0, x, 3 * kNodes, &needed));
  CHECK(needed == 3 * kNodes && memcmp(x, nodes, sizeof x) == 0, "the rest positions are not the nodes given");
  OK(corofem_simulation_read_elements(sim, 0, read_tets, 4 * kTets, &needed));
  CHECK(needed == 4 * kTets, "needed %zu element indices", needed);
  for (i = 0; i < kTets; ++i) { /* the same four nodes (a negatively oriented one is reordered) */
    int same = 0, p, q;
    for (p = 0; p < 4; ++p)
      for (q = 0; q < 4; ++q) same += read_tets[4 * i + (size_t)p] == tets[4 * i + (size_t)q];
    CHECK(same == 4, "element %zu has other nodes than given", i);
  }

  /* No gravity (the scene has none): moved by (1, 2, 3) m it lies there exactly; launched at
   * 1 m/s in z it translates rigidly by 1 m/s x 0.01 s per step. */
  OK(corofem_simulation_teleport(sim, 0, NULL, move));
  OK(corofem_simulation_read_positions(sim, 0, x, 3 * kNodes, NULL));
  for (i = 0; i < 3 * kNodes; ++i)
    CHECK(fabs(x[i] - (nodes[i] + move[i % 3])) <= 1e-12, "teleported coordinate %zu is %.15f", i, x[i]);
  for (i = 0; i < kNodes; ++i) {
    v[3 * i] = v[3 * i + 1] = 0.0;
    v[3 * i + 2] = 1.0;
  }
  OK(corofem_simulation_set_velocities(sim, 0, v, 3 * kNodes));
  OK(corofem_simulation_step(sim, NULL));
  OK(corofem_simulation_read_positions(sim, 0, x, 3 * kNodes, NULL));
  for (i = 0; i < kNodes; ++i)
    for (a = 0; a < 3; ++a)
      CHECK(fabs(x[3 * i + (size_t)a] - (nodes[3 * i + (size_t)a] + move[a] + (a == 2 ? 0.01 : 0.0))) <= 1e-9,
            "launched node %zu, axis %d: %.12f", i, a, x[3 * i + (size_t)a]);
  OK(corofem_simulation_read_velocities(sim, 0, v, 3 * kNodes, NULL));
  CHECK(fabs(v[2] - 1.0) <= 1e-9 && fabs(v[0]) <= 1e-9, "velocity (%.12f, %.12f, %.12f) after the step", v[0], v[1], v[2]);
  {
    corofem_energies e;
    OK(corofem_simulation_energies(sim, 0, &e));
    CHECK(fabs(e.kinetic - 0.5 * 1000.0 * 0.004 * 1.0) <= 1e-9 && fabs(e.elastic) <= 1e-9,
          "kinetic %.12f J (0.5 m v^2 = 2 J), elastic %.3g J", e.kinetic, e.elastic);
  }
  /* set_positions puts the body anywhere; reset_body back at rest. */
  OK(corofem_simulation_set_positions(sim, 0, nodes, 3 * kNodes));
  OK(corofem_simulation_read_positions(sim, 0, x, 3 * kNodes, NULL));
  CHECK(memcmp(x, nodes, sizeof x) == 0, "set_positions did not set them");
  OK(corofem_simulation_set_velocities(sim, 0, v, 3 * kNodes));
  OK(corofem_simulation_set_gravity(sim, zero));
  OK(corofem_simulation_step(sim, NULL));
  OK(corofem_simulation_reset_body(sim, 0));
  OK(corofem_simulation_read_positions(sim, 0, x, 3 * kNodes, NULL));
  CHECK(memcmp(x, nodes, sizeof x) == 0, "reset_body did not put the body back at rest");
  OK(corofem_simulation_read_velocities(sim, 0, v, 3 * kNodes, NULL));
  for (i = 0; i < 3 * kNodes; ++i) CHECK(v[i] == 0.0, "velocity %zu is %g after reset_body", i, v[i]);
  corofem_simulation_destroy(sim);
}

/* The text reports and the surface queries of a body without a surface. */
static void reports(void) {
  corofem_simulation* sim = create_beam();
  size_t needed = 0, vertices = 1, triangles = 1;
  char small[4];
  char* text;
  corofem_gpu_buffer buffer;
  double p[3];

  OK(corofem_simulation_plan_report(sim, NULL, 0, &needed));
  CHECK(needed > 10, "the plan needs %zu chars", needed);
  text = (char*)malloc(needed);
  if (!text) exit(2);
  OK(corofem_simulation_plan_report(sim, text, needed, &needed));
  CHECK(strlen(text) + 1 == needed && contains(text, "\"bodies\""), "the plan: %s", text);
  free(text);
  FAILS(corofem_simulation_plan_report(sim, small, sizeof small, &needed), COROFEM_BAD_INPUT, "are needed");
  OK(corofem_simulation_scheduler_report(sim, NULL, 0, &needed));
  text = (char*)malloc(needed);
  if (!text) exit(2);
  OK(corofem_simulation_scheduler_report(sim, text, needed, NULL));
  CHECK(contains(text, "\"choice\"") && contains(text, "reference"), "the scheduler's report: %s", text);
  free(text);
  text = (char*)malloc(64);
  if (!text) exit(2);
  OK(corofem_simulation_backend_name(sim, text, 64, NULL));
  CHECK(strcmp(text, "reference") == 0, "backend %s", text);
  OK(corofem_simulation_device_name(sim, text, 64, NULL));
  CHECK(strlen(text) > 0, "no device name");
  free(text);

  OK(corofem_simulation_surface_size(sim, 0, &vertices, &triangles));
  CHECK(vertices == 0 && triangles == 0, "a body without a surface has %zu vertices, %zu triangles", vertices, triangles);
  FAILS(corofem_simulation_read_surface(sim, 0, p, 3, NULL, 0, &needed), COROFEM_BAD_INPUT, "has no surface");
  FAILS(corofem_simulation_update_surface(sim, 0), COROFEM_BAD_INPUT, "has no surface");
  memset(&buffer, 0xff, sizeof buffer);
  OK(corofem_simulation_surface_buffer(sim, 0, &buffer));
  CHECK(buffer.api == COROFEM_GPU_NONE && buffer.handle == 0 && buffer.bytes == 0, "an empty buffer has api %d",
        (int)buffer.api);
  corofem_simulation_destroy(sim);
}

int main(int argc, char** argv) {
  if (argc != 3) {
    fprintf(stderr, "usage: capi_test SCENE.json EXPECTED_VERSION\n");
    return 2;
  }
  versions(argv[2]);
  scene_errors(argv[1]);
  drag_tip();
  hold_and_push();
  memory_mesh();
  reports();
  if (failures) {
    fprintf(stderr, "%d check(s) failed\n", failures);
    return 1;
  }
  printf("capi_test: every check passed (corofem %s)\n", corofem_version());
  return 0;
}
