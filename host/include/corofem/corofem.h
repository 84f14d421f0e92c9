/* corofem's C API: the library for engines and languages that bind C (Unity, Godot and Unreal
 * plug-ins, Python's ctypes). C99; compiles as C and as C++. A thin layer over the C++ API
 * (corofem/simulation.hpp), whose comments give each call's physics in full.
 *
 *   corofem_scene* scene = NULL;
 *   if (corofem_scene_parse(json_text, "", NULL, 0, &scene) != COROFEM_OK) {
 *     fprintf(stderr, "%s\n", corofem_last_error_message());
 *     return 2;
 *   }
 *   corofem_simulation* sim = NULL;
 *   corofem_status s = corofem_simulation_create(scene, NULL, &sim);
 *   corofem_scene_destroy(scene);              (the simulation keeps its own copy)
 *   ...
 *   s = corofem_simulation_step_dt(sim, 1.0 / 90.0, NULL);
 *   s = corofem_simulation_read_positions(sim, 0, x, capacity, &needed);
 *   corofem_simulation_destroy(sim);
 *
 * Rules that hold for every call:
 *
 * - Errors. Every call that can fail returns a corofem_status and sets the calling thread's last
 *   error: COROFEM_OK with an empty message on success, else the code and a message that names the
 *   place and the fix (corofem_last_error_message()). The message is the library's copy, valid
 *   until the next corofem call on the same thread; copy it to keep it. Calls that return no
 *   corofem_status (versions, names, the error queries, destroy, defaults) leave it alone. The
 *   last error is per thread, so that Simulations stepped on different threads do not overwrite
 *   each other's messages.
 * - No exception crosses the API: every entry point catches everything (an unexpected one is
 *   COROFEM_INTERNAL).
 * - Out parameters are written only on success (except `needed`, see below, and a step's report,
 *   filled as far as the step went). A NULL handle or a NULL pointer where an array or a value is
 *   required is COROFEM_BAD_INPUT.
 * - Arrays belong to the caller. A read takes the caller's array and its capacity in elements, and
 *   writes the number of elements it needs to *needed (when `needed` is not NULL). An array of
 *   NULL with capacity 0 asks for the size only (COROFEM_OK, nothing read). A smaller capacity is
 *   COROFEM_BAD_INPUT and nothing is written to the array. Text is read the same way, its size
 *   counting the terminating NUL.
 * - Threads: one handle is used from one thread at a time; different simulations may run on
 *   different threads.
 * - Indices: bodies are numbered from 0 in the scene's order; nodes are 0-based indices into the
 *   body's mesh as loaded (the file's order, or the order of corofem_scene_set_body_mesh).
 *   Vectors are 3 doubles (x, y, z) in SI units (m, m/s, N, m/s^2); rotations are 9 doubles, row
 *   by row.
 *
 * The library is static by default (libcorofem.a, target corofem::corofem, which holds this API
 * too); the build also makes libcorofem_c.so (target corofem::corofem_c), a shared library that
 * exports this API alone, for loaders such as ctypes (docs/embedding.md, "The C API"). */
#ifndef COROFEM_COROFEM_H
#define COROFEM_COROFEM_H

#include <corofem/version.h> /* COROFEM_VERSION_MAJOR, _MINOR, _PATCH, _STRING (made by the build) */

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ------------------------------------------------------------------ versions and errors */

/** The library's version, "MAJOR.MINOR.PATCH"; compare with COROFEM_VERSION_STRING to detect a
 *  header that does not belong to the library loaded. Static storage. */
const char* corofem_version(void);

/** What kind of failure; the same values as corofem::ErrorCode. */
typedef enum corofem_status {
  COROFEM_OK = 0,
  COROFEM_BAD_INPUT = 1,       /**< malformed file or text, invalid value, NULL pointer, small array */
  COROFEM_SOLVE_FAILED = 2,    /**< a solve did not converge or the state became non-finite */
  COROFEM_DEVICE_ERROR = 3,    /**< an OpenCL or Vulkan call failed */
  COROFEM_NOT_COMPILED_IN = 4, /**< the backend or feature was not built into this library */
  COROFEM_IO_ERROR = 5,        /**< a file could not be opened, read or written */
  COROFEM_INTERNAL = 6         /**< a bug in corofem: please report it */
} corofem_status;

/** The name of a status ("ok", "bad input", ...; "unknown" for a value that is none). Static. */
const char* corofem_status_name(corofem_status status);
/** The status of the last corofem call on this thread that returned one. */
corofem_status corofem_last_status(void);
/** Its message ("" after a success): valid until the next corofem call on this thread. */
const char* corofem_last_error_message(void);

/* ------------------------------------------------------------------ input limits */

/** The largest inputs corofem reads or generates (corofem::InputLimits): a guard against a wrong
 *  path or a corrupt file exhausting the memory. A file or box over a limit is COROFEM_BAD_INPUT
 *  naming the limit. A field of 0 takes its default, so a zeroed struct is the defaults. */
typedef struct corofem_input_limits {
  uint64_t max_input_bytes; /**< bytes: the largest mesh, surface or .bou file read (default 1 GiB) */
  uint64_t max_scene_bytes; /**< bytes: the largest scene file read (default 16 MiB) */
  uint64_t max_box_tets;    /**< tetrahedra: the largest generated box, a scene's "box" mesh (default 50,000,000) */
} corofem_input_limits;

/** The default limits: 1 GiB (1073741824 bytes), 16 MiB (16777216 bytes), 50,000,000 tetrahedra. */
corofem_input_limits corofem_default_input_limits(void);

/* ------------------------------------------------------------------ scenes */

/** A scene: what to simulate (docs/scene-format.md). */
typedef struct corofem_scene corofem_scene;

/** Loads a JSON scene file. `overrides`: `override_count` "key.path=value" strings applied before
 *  validation (the command's --set; NULL with 0 for none). Relative paths in the scene are
 *  relative to the file's folder. On success *scene is a new scene (corofem_scene_destroy). */
corofem_status corofem_scene_load(const char* path, const char* const* overrides, size_t override_count,
                                  corofem_scene** scene);
/** Parses a scene from JSON text; relative paths in it resolve against `base_dir` (NULL or "": the
 *  process's working folder). Otherwise as corofem_scene_load. */
corofem_status corofem_scene_parse(const char* json, const char* base_dir, const char* const* overrides,
                                   size_t override_count, corofem_scene** scene);
/** corofem_scene_load under `limits` (NULL: the defaults): the scene file at most
 *  limits->max_scene_bytes, a "box" mesh at most limits->max_box_tets tetrahedra. The meshes and
 *  other files the scene names are read by corofem_simulation_create, under its options' limits. */
corofem_status corofem_scene_load_with_limits(const char* path, const char* const* overrides, size_t override_count,
                                              const corofem_input_limits* limits, corofem_scene** scene);
/** corofem_scene_parse under `limits` (NULL: the defaults): a "box" mesh at most
 *  limits->max_box_tets tetrahedra. */
corofem_status corofem_scene_parse_with_limits(const char* json, const char* base_dir, const char* const* overrides,
                                               size_t override_count, const corofem_input_limits* limits,
                                               corofem_scene** scene);
/** Frees a scene (NULL: nothing). Simulations made from it keep their own copy. */
void corofem_scene_destroy(corofem_scene* scene);
corofem_status corofem_scene_body_count(const corofem_scene* scene, int* count);
/** Sets the steps (dynamics) or load increments (statics) the analysis takes: for a dynamic
 *  analysis `steps` >= 0, 0 making it open-ended (it steps until the application stops: the frame
 *  loop of an interactive application, which a scene file cannot say); for a static one >= 1. */
corofem_status corofem_scene_set_step_count(corofem_scene* scene, int steps);
/** Gives body `body` a mesh from the caller's memory in place of the file or box its scene text
 *  names (which a scene needs to parse: any small "box" will do): `node_count` nodes of 3 doubles
 *  (m) and `tet_count` tetrahedra of 4 node indices (0-based). The arrays are copied. The body's
 *  "scale" and "translate" still apply. The mesh is checked (indices, repeated nodes, finite
 *  coordinates, volumes) and inverted elements reoriented when a simulation is created. */
corofem_status corofem_scene_set_body_mesh(corofem_scene* scene, int body, const double* nodes, size_t node_count,
                                           const uint32_t* tets, size_t tet_count);

/* ------------------------------------------------------------------ creation */

/** The API of a GPU handle (corofem::GpuApi). */
typedef enum corofem_gpu_api {
  COROFEM_GPU_NONE = 0,   /**< no handle */
  COROFEM_GPU_OPENCL = 1, /**< cl_mem, cl_context, cl_command_queue, cl_device_id */
  COROFEM_GPU_VULKAN = 2  /**< VkBuffer, VkInstance, VkPhysicalDevice, VkDevice, VkQueue */
} corofem_gpu_api;

/** The application's own device, lent to corofem (corofem::ExternalDevice), which uses it while it
 *  lives and never destroys it. COROFEM_GPU_OPENCL: its cl_context, an in-order cl_command_queue on
 *  it and that queue's cl_device_id, all three (retained while used). COROFEM_GPU_VULKAN: instance,
 *  physical_device, device (Vulkan 1.1 or later), a queue of family queue_family that supports
 *  compute, and shader_float64 = 1 when the device was created with that feature (double precision
 *  needs it); no other thread may submit to that queue during a corofem call, and the application
 *  waits for its own work reading corofem's buffers before destroying the simulation. */
typedef struct corofem_external_device {
  corofem_gpu_api api; /**< COROFEM_GPU_NONE: none lent (the default) */
  void* context;       /**< OpenCL: cl_context */
  void* queue;         /**< OpenCL: cl_command_queue; Vulkan: VkQueue */
  void* device;        /**< OpenCL: cl_device_id; Vulkan: VkDevice */
  void* instance;        /**< Vulkan: VkInstance */
  void* physical_device; /**< Vulkan: VkPhysicalDevice */
  uint32_t queue_family; /**< Vulkan: the family of queue */
  int shader_float64;    /**< Vulkan: 1 when device has shaderFloat64 enabled */
} corofem_external_device;

/** What an application adds to a scene at creation (corofem::SimulationOptions). */
typedef struct corofem_options {
  /** Where every body runs, in order of preference, `device_count` strings "<backend>" or
   *  "<backend>:<device>" ("opencl:1", "reference"); the reference backend is always the last
   *  resort. NULL with 0 (the default): the scene's "backend" decides. */
  const char* const* devices;
  size_t device_count;
  /** The application's OpenCL or Vulkan device: every body runs there, the surfaces' buffers live
   *  on it. */
  corofem_external_device device;
  /** The largest mesh, surface and .bou files read and boxes generated (creation and
   *  corofem_simulation_add_body; max_scene_bytes is not used here). Zeroed: the defaults. */
  corofem_input_limits limits;
} corofem_options;

/** The default options: no device order, no device lent, the default input limits. */
corofem_options corofem_default_options(void);

/** A scene compiled for its backends, advanced step by step. */
typedef struct corofem_simulation corofem_simulation;

/** Loads the meshes, builds every body and its device. `options`: NULL for the defaults. The scene
 *  is copied; it may be destroyed afterwards. On success *simulation is new
 *  (corofem_simulation_destroy). */
corofem_status corofem_simulation_create(const corofem_scene* scene, const corofem_options* options,
                                         corofem_simulation** simulation);
/** Compiles and caches ahead of time what creating and stepping the scene compiles (the kernels of
 *  its plan, the scheduler's calibration), so that a later corofem_simulation_create on this machine
 *  does not wait for them (corofem::warmUp). `options` may be NULL; `*seconds` (if not NULL) gets
 *  the time it took. */
corofem_status corofem_warm_up(const corofem_scene* scene, const corofem_options* options, double* seconds);
/** Frees a simulation and its device memory (NULL: nothing). */
void corofem_simulation_destroy(corofem_simulation* simulation);

/* ------------------------------------------------------------------ stepping */

/** What one step (dynamics) or one load increment (statics) did, summed over bodies. */
typedef struct corofem_step_report {
  int step;               /**< 1-based index of the step or increment just taken */
  double time;            /**< simulated time after the step (s); statics: the load factor */
  int newton_iterations;  /**< Newton iterations, summed over bodies */
  int linear_iterations;  /**< PCG iterations, summed over bodies and Newton iterations */
  double residual;        /**< largest final relative Newton residual over bodies */
  double linear_residual; /**< largest final relative PCG residual over bodies */
  int converged;          /**< 1 when every body's solves converged, else 0 */
  double wall_seconds;    /**< wall time of the step (s) */
} corofem_step_report;

/** One time step of the scene's time_step (dynamics) or one load increment (statics). A failed
 *  solve (COROFEM_SOLVE_FAILED) keeps every body's state before the step and is not terminal: the
 *  next step starts the bodies that failed at rest. `report`: NULL or filled as far as the step
 *  went. */
corofem_status corofem_simulation_step(corofem_simulation* simulation, corofem_step_report* report);
/** One time step of `dt` seconds (> 0; dynamics only: an application's frame time). */
corofem_status corofem_simulation_step_dt(corofem_simulation* simulation, double dt, corofem_step_report* report);
/** 1 when every step of the analysis is done (never, for an open-ended one: steps = 0), else 0. */
corofem_status corofem_simulation_finished(const corofem_simulation* simulation, int* finished);
corofem_status corofem_simulation_steps_taken(const corofem_simulation* simulation, int* steps);
/** The steps (increments) the analysis asks for; 0 for an open-ended dynamic analysis. */
corofem_status corofem_simulation_step_count(const corofem_simulation* simulation, int* steps);
/** Simulated time (dynamics, s) or load factor (statics). */
corofem_status corofem_simulation_time(const corofem_simulation* simulation, double* time);

/* ------------------------------------------------------------------ bodies and reads */

corofem_status corofem_simulation_body_count(const corofem_simulation* simulation, int* count);
/** The index of the body named `name` in the scene. */
corofem_status corofem_simulation_find_body(const corofem_simulation* simulation, const char* name, int* body);
corofem_status corofem_simulation_node_count(const corofem_simulation* simulation, int body, size_t* count);
corofem_status corofem_simulation_element_count(const corofem_simulation* simulation, int body, size_t* count);
/** The body's rest node positions (its mesh as loaded, scaled and moved), 3 doubles per node (m):
 *  3 * node count elements. */
corofem_status corofem_simulation_read_rest_positions(const corofem_simulation* simulation, int body,
                                                      double* positions, size_t capacity, size_t* needed);
/** The body's tetrahedra, 4 node indices each (0-based, positively oriented): 4 * element count
 *  elements. */
corofem_status corofem_simulation_read_elements(const corofem_simulation* simulation, int body, uint32_t* tets,
                                                size_t capacity, size_t* needed);
/** The body's current node positions, 3 doubles per node (m): 3 * node count elements. */
corofem_status corofem_simulation_read_positions(const corofem_simulation* simulation, int body, double* positions,
                                                 size_t capacity, size_t* needed);
/** The body's current velocities, 3 doubles per node (m/s). */
corofem_status corofem_simulation_read_velocities(const corofem_simulation* simulation, int body, double* velocities,
                                                  size_t capacity, size_t* needed);

/** Energies of one body at the current state (J). */
typedef struct corofem_energies {
  double elastic;       /**< strain energy of the formulation */
  double kinetic;       /**< 1/2 v^T M v with the lumped mass */
  double external_work; /**< work of the external loads since the start */
} corofem_energies;
corofem_status corofem_simulation_energies(const corofem_simulation* simulation, int body, corofem_energies* energies);

/* ------------------------------------------------------------------ render surfaces */

/** The size of the body's render surface (the scene's "surface"): 0 and 0 for a body without one. */
corofem_status corofem_simulation_surface_size(const corofem_simulation* simulation, int body, size_t* vertices,
                                               size_t* triangles);
/** The surface's triangles, 3 vertex indices each (0-based): 3 * triangle count elements. */
corofem_status corofem_simulation_read_surface_triangles(const corofem_simulation* simulation, int body,
                                                         uint32_t* triangles, size_t capacity, size_t* needed);
/** The deformed surface at the current state: 3 doubles per vertex (m) into `positions` and, when
 *  `normals` is not NULL, the smooth unit normals, 3 floats per vertex; both need 3 * vertex count
 *  elements (*needed). On a device that computes surfaces (OpenCL, Vulkan) this is the explicit read-back
 *  of the device's buffer (positions float-rounded). COROFEM_BAD_INPUT for a body without a
 *  surface. */
corofem_status corofem_simulation_read_surface(const corofem_simulation* simulation, int body, double* positions,
                                               size_t positions_capacity, float* normals, size_t normals_capacity,
                                               size_t* needed);

/** A region of a device buffer holding vertices (corofem::GpuBuffer): vertex v at byte
 *  offset + v * stride of the buffer `handle`. */
typedef struct corofem_gpu_buffer {
  corofem_gpu_api api; /**< COROFEM_GPU_NONE: no buffer */
  uint64_t handle;     /**< OpenCL: the cl_mem, as an integer; Vulkan: the VkBuffer; 0: none */
  size_t offset;       /**< bytes from the buffer's start to the first vertex */
  size_t stride;       /**< bytes from one vertex to the next */
  size_t bytes;        /**< bytes of the region: vertex count * stride */
} corofem_gpu_buffer;

/** The device buffer of the deformed surface (Simulation::surfaceBuffer): with the interleaved
 *  layout 6 float32 per vertex (position, unit normal; a 24-byte stride), with "surface_layout":
 *  "separate" 3 float32 of position (12 bytes). An empty buffer (api COROFEM_GPU_NONE, handle 0)
 *  where the body has no surface or its surface is computed on the host (the reference backend).
 *  Enqueues the update on the device's queue and does not wait (corofem_simulation_update_surface
 *  waits); on Vulkan the update ends with a barrier to every read of every later command on that
 *  queue, so a draw the application submits to the queue it lent afterwards sees the current
 *  surface. The buffer belongs to the simulation: ask again after each step rather than keep it. */
corofem_status corofem_simulation_surface_buffer(const corofem_simulation* simulation, int body,
                                                 corofem_gpu_buffer* buffer);
/** With "surface_layout": "separate", the buffer of the unit normals (3 float32 per vertex); else
 *  empty. */
corofem_status corofem_simulation_surface_normal_buffer(const corofem_simulation* simulation, int body,
                                                        corofem_gpu_buffer* buffer);
/** Brings the device surface of `body` up to date and waits for it (nothing to do on the host
 *  path). COROFEM_BAD_INPUT for a body without a surface. */
corofem_status corofem_simulation_update_surface(const corofem_simulation* simulation, int body);

/* ------------------------------------------------------------------ run-time control
 * Dynamic analyses only (COROFEM_BAD_INPUT on a static one). Each call takes effect at the next
 * step and lasts until changed. */

/** Grabs the listed nodes (`count` >= 1) of a body with a handle, a hard constraint: from the next
 *  step on they follow the handle's target exactly. *handle receives its id (> 0). A node held by
 *  a newer handle or pin leaves the older one. */
corofem_status corofem_simulation_add_handle_nodes(corofem_simulation* simulation, int body, const uint32_t* nodes,
                                                   size_t count, int* handle);
/** Grabs the nodes within `radius` (m, >= 0) of `point` (m) at the body's current positions, or the
 *  node nearest `point` when none is that near. */
corofem_status corofem_simulation_add_handle_point(corofem_simulation* simulation, int body, const double point[3],
                                                   double radius, int* handle);
/** Grabs the four nodes the body's render-surface vertex `vertex` is bound to; the handle's target
 *  then places that vertex itself, which follows it exactly. */
corofem_status corofem_simulation_add_handle_surface_vertex(corofem_simulation* simulation, int body, int vertex,
                                                            int* handle);
/** Moves a handle: each held node goes to target + R (g - c) at the end of the next step, g its
 *  position when grabbed, c the centroid of those positions; `target` is where c goes (m).
 *  `rotation`: 9 doubles row by row, or NULL for none. */
corofem_status corofem_simulation_move_handle(corofem_simulation* simulation, int handle, const double target[3],
                                              const double* rotation);
/** Releases a handle's nodes (free again, or back to the scene's supports where it fixed them). */
corofem_status corofem_simulation_remove_handle(corofem_simulation* simulation, int handle);
/** Makes a handle a spring of `stiffness` N/m (> 0) that pulls its nodes towards the target and
 *  holds none of them (node k by stiffness w_k, w_k = 1/n, or a surface vertex's weights: the whole
 *  force is stiffness times the stretch), or a hard constraint again (0), from the next step on. */
corofem_status corofem_simulation_set_handle_stiffness(corofem_simulation* simulation, int handle, double stiffness);
/** Pins `count` nodes of a body where they are now until unpinned. */
corofem_status corofem_simulation_pin_nodes(corofem_simulation* simulation, int body, const uint32_t* nodes,
                                            size_t count);
/** Frees nodes: pinned ones, and those the scene fixes or prescribes. Held nodes stay held. */
corofem_status corofem_simulation_unpin_nodes(corofem_simulation* simulation, int body, const uint32_t* nodes,
                                              size_t count);

/** A force the application applies to a body (corofem::AppliedForce). */
typedef struct corofem_force {
  int node;        /**< the node, or -1: at `point` */
  double point[3]; /**< (m), with node = -1: spread over the element that contains it (barycentric) */
  double force[3]; /**< (N) */
} corofem_force;

/** Replaces the forces the application applies to a body (added to the scene's loads); `count` 0
 *  (forces may be NULL) removes them. */
corofem_status corofem_simulation_set_forces(corofem_simulation* simulation, int body, const corofem_force* forces,
                                             size_t count);
/** Adds body `body` of `scene` (a scene handle from corofem_scene_parse or _load, e.g. the text of
 *  one body, with an in-memory mesh from corofem_scene_set_body_mesh) to the live simulation: it
 *  runs on a device of its own from its rest state and its own time 0, as in a fresh simulation;
 *  the other bodies go on. File paths in it are relative to the simulation's scene folder. *index
 *  receives its index (the body count - 1). Its name must differ from the others'. */
corofem_status corofem_simulation_add_body(corofem_simulation* simulation, const corofem_scene* scene, int body,
                                           int* index);
/** Removes a body with its handles and frees its device memory; later bodies' indices move down by
 *  one. A body batched with others leaves the batch: its device is made again for the others, which
 *  keep their state (their surface buffers are new ones: ask for them again). COROFEM_DEVICE_ERROR,
 *  with nothing changed, where that device cannot be made; COROFEM_BAD_INPUT for the last body. */
corofem_status corofem_simulation_remove_body(corofem_simulation* simulation, int body);
/** Changes a body's material from the next step: Young's modulus (Pa, > 0), Poisson's ratio
 *  (-1 < nu < 0.5), Rayleigh damping alpha (1/s, >= 0) and beta (s, >= 0); its density stays. */
corofem_status corofem_simulation_set_material(corofem_simulation* simulation, int body, double youngs_modulus,
                                               double poisson_ratio, double rayleigh_mass, double rayleigh_stiffness);
/** Replaces the gravity of every body (m/s^2; at once, no ramp). */
corofem_status corofem_simulation_set_gravity(corofem_simulation* simulation, const double gravity[3]);
/** Sets a body's node positions: `count` = 3 * node count doubles (m); velocities stay. Held nodes
 *  are moved back to their targets by the next step. */
corofem_status corofem_simulation_set_positions(corofem_simulation* simulation, int body, const double* positions,
                                                size_t count);
/** Sets a body's velocities: `count` = 3 * node count doubles (m/s; held dofs keep zero). */
corofem_status corofem_simulation_set_velocities(corofem_simulation* simulation, int body, const double* velocities,
                                                 size_t count);
/** Puts a body back at rest: rest positions, zero velocities (its handles, pins and forces stay). */
corofem_status corofem_simulation_reset_body(corofem_simulation* simulation, int body);
/** Moves a body rigidly: x -> R x + t, v -> R v, with its pins and handles. `rotation`: 9 doubles
 *  row by row, or NULL for none; `translation` (m). COROFEM_BAD_INPUT for a body the scene fixes or
 *  prescribes (unpin those nodes first) or an R that is not a rotation. */
corofem_status corofem_simulation_teleport(corofem_simulation* simulation, int body, const double* rotation,
                                           const double translation[3]);

/* ------------------------------------------------------------------ reports (text) */

/** "reference", "opencl". */
corofem_status corofem_simulation_backend_name(const corofem_simulation* simulation, char* text, size_t capacity,
                                               size_t* needed);
/** e.g. "host (Eigen, double)" or the OpenCL or Vulkan device's name. */
corofem_status corofem_simulation_device_name(const corofem_simulation* simulation, char* text, size_t capacity,
                                              size_t* needed);
/** Where the bodies run and why, as JSON text (Simulation::schedulerReport). */
corofem_status corofem_simulation_scheduler_report(const corofem_simulation* simulation, char* text, size_t capacity,
                                                   size_t* needed);
/** The plan of the scene as JSON text: per body backend, kernels, buffers, bytes per step
 *  (Simulation::planReport; docs/scene-format.md, "Scheduling and plans"). */
corofem_status corofem_simulation_plan_report(const corofem_simulation* simulation, char* text, size_t capacity,
                                              size_t* needed);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* COROFEM_COROFEM_H */
