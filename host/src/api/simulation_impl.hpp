// The Simulation's inside (api/): the bodies (mesh, problem, schedule, render surface, sleep), the
// groups of bodies that share a device (a DeviceSlot with its failover, and the driver that steps
// them), and the surfaces on the devices. simulation.cpp is the façade, reports.cpp the JSON
// reports, surfaces.cpp the render surfaces.
#pragma once

#include <corofem/simulation.hpp>

#include "model/problem.hpp"
#include "schedule/scheduler.hpp"
#include "solve/device_slot.hpp"
#include "solve/driver.hpp"
#include "util/log.hpp"
#include "util/parallel.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace corofem {

struct Simulation::Impl {
  struct Body {
    TetMesh mesh;
    MeshReadReport report;
    // Heap-held: the slot and the driver keep references to it.
    std::unique_ptr<detail::Problem> problem;
    detail::BodySchedule schedule;
    std::size_t group = 0;  ///< index into groups
    std::size_t index = 0;  ///< the body's index in its group's slot and driver
    // Render surface bound to the tet mesh (paper Sec. 5), when the body names one.
    std::unique_ptr<SurfaceMesh> surface;
    std::unique_ptr<SurfaceBinding> binding;
    bool separateStreams = false;  ///< BodyDesc::surfaceLayout == Separate
    /// What the application holds the body by (control.cpp), handed to the driver (and the
    /// constraints to the device) at the next step.
    struct Hold {
      static constexpr int kScene = -1, kReleased = -2, kPinned = 0;  ///< holder[n]; > 0: a handle id
      std::vector<std::uint8_t> scene;  ///< Problem::constrained as the scene made it (3N)
      std::vector<int> holder;          ///< per node: kScene, kReleased, kPinned or the handle's id
      Eigen::VectorXd targets;          ///< 3N: held dofs' targets, NaN elsewhere (empty: none yet)
      Eigen::VectorXd forces;           ///< 3N applied forces (empty: none)
      /// 3N: the spring handles' stiffness per dof (N/m) and where they pull it (m), combined over
      /// the handles as sum k and sum k t / sum k; empty: none (rebuildSprings).
      Eigen::VectorXd springStiffness, springTargets;
      bool constraintsChanged = false, controlsChanged = false, materialChanged = false, springsChanged = false;
      bool restart = false;  ///< the last step failed: the next starts from the positions at rest
    } hold;
    // Sleep (analysis.sleep): quiet steps so far, whether the body sleeps, and the loads and
    // prescribed positions it fell asleep under (the reference a change is measured against).
    struct Sleep {
      bool asleep = false;
      int quiet = 0;
      long long sleptSteps = 0, wakes = 0;
      Eigen::VectorXd fRef, xpRef;
    } sleep;
  };

  /// The surfaces of some of a group's bodies on its device, updated together (one output layout).
  struct SurfaceSet {
    std::unique_ptr<detail::DeviceSurfaces> surfaces;
    std::vector<std::size_t> bodies;  ///< scene body indices, in member order
    bool dirty = true;                ///< a body stepped since the last update
    bool own = false;                 ///< one body's, because the group's could not be made together
  };

  /// Bodies that run on one device: all the bodies scheduled on one device that batches (a batch,
  /// sharing its buffers and launches), or one body.
  struct Group {
    std::vector<std::size_t> bodies;  ///< scene indices, in the slot's order
    std::unique_ptr<detail::DeviceSlot> slot;
    std::unique_ptr<detail::Driver> driver;
    bool batch = false;               ///< formed as a batch of two or more bodies
    std::string candidate;            ///< the device's candidate label when formed
    std::vector<SurfaceSet> surfaces; ///< on the device (none on a host device)
    /// The slot's generation the surfaces were made for (a failover makes them again).
    std::size_t surfacesFor = std::numeric_limits<std::size_t>::max();
    std::string surfacesNotShared;    ///< why the group's surfaces could not be made together
    std::string surfacesOnHost;       ///< why some could not be made on the device at all
  };

  /// A set of bodies that could have shared a device but runs unbatched, and why.
  struct Unbatched {
    std::vector<std::size_t> bodies;
    std::string candidate, reason;
  };

  Scene scene;
  detail::Log log;                  ///< SimulationOptions::log; the drivers and slots hold a reference
  detail::DeviceOptions device;     ///< SimulationOptions::opencl, device
  detail::TaskRunnerFn tasks;       ///< SimulationOptions::tasks (empty: the library's pool)
  std::vector<std::string> devices; ///< SimulationOptions::devices
  InputLimits inputLimits;          ///< SimulationOptions::inputLimits (create, addBody)
  std::vector<Body> bodies;
  std::vector<Group> groups;
  std::vector<Unbatched> unbatched;
  int stepsTaken = 0;
  double time = 0.0;  ///< dynamics: the simulated time of the last completed step (s)

  /// A handle (addHandle): its body, nodes, their positions when grabbed and their centroid.
  struct Handle {
    std::size_t body = 0;
    std::vector<std::uint32_t> nodes;
    std::vector<int> previous;    ///< per node: its holder before the handle took it (Hold::holder)
    std::vector<double> grabbed;  ///< 3 per node (m)
    /// The point the target places: the grabbed nodes' centroid, or a surface vertex's position.
    double centroid[3] = {0, 0, 0};
    double target[3] = {0, 0, 0};    ///< the last target (m)
    double rotation[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  ///< the last rotation, row-major
    /// 0: a hard constraint (the handle holds its nodes: Hold::holder). > 0: a spring of this
    /// stiffness (N/m) that holds nothing; node k's share of it is weights[k] (they sum to 1).
    double stiffness = 0.0;
    std::vector<double> weights;
  };
  std::map<int, Handle> handles;
  int nextHandle = 1;

  // The drivers and slots go first (they refer to the problems).
  ~Impl() { groups.clear(); }

  bool isStatic() const { return scene.analysis.kind == AnalysisDesc::Kind::Static; }
  /// Increments (statics, at least 1) or steps (dynamics; 0: open-ended).
  int stepCount() const {
    return isStatic() ? std::max(1, scene.analysis.statics.increments) : std::max(0, scene.analysis.dynamics.steps);
  }
  const Body& body(int index) const;
  Body& bodyForSurface(int index);
  detail::Driver& driverOf(const Body& b) const { return *groups[b.group].driver; }
  detail::DeviceSlot& slotOf(const Body& b) const { return *groups[b.group].slot; }

  // -- set-up (simulation.cpp)
  /// A body of the scene: its mesh, surface, problem and schedule (not yet in a group).
  Body makeBody(const BodyDesc& desc) const;
  /// The groups: batches of the bodies whose first candidate is the same device of a backend that
  /// batches (backend.batch on), each other body alone. A batch that cannot be made leaves its
  /// bodies unbatched, with the reason.
  void formGroups();
  void makeGroup(std::vector<std::size_t> members, bool batch);

  // -- steps (simulation.cpp)
  /// Steps every body of the group (sleeping ones idle): outcomes per group body.
  std::vector<detail::BodyOutcome> stepGroup(Group& g, const detail::StepCall& call);
  /// One step (of length h, dynamics) of every group, summed into r (step() and step(dt)).
  void stepAll(double h, StepReport& r);

  // -- run-time control (control.cpp)
  /// A body for a control call: in range, and the analysis dynamic.
  Body& controlled(int index, const char* call);
  /// Hands the group's changed holds to its device and driver (before a step).
  void applyHolds(Group& g);
  /// The body's controls changed: wake it, its surfaces are stale.
  void touched(Body& b);
  /// Recomputes the targets of the nodes of handle `id` (target and rotation given).
  void placeHandle(int id, const double target[3], const double* rotation);
  /// Handle `id`, or BadInput naming `call` where there is none.
  Handle& handleFor(int id, const char* call);
  /// A hard handle takes its nodes from their holders (remembering them), or gives them back.
  void takeNodes(int id);
  void releaseNodes(int id);
  /// The body's combined springs from its spring handles' stiffness, weights and targets.
  void rebuildSprings(Body& b);

  // -- surfaces (surfaces.cpp)
  /// surfaceBuffer (normals false) or surfaceNormalBuffer (true) of a body: empty where there is none.
  GpuBuffer surfaceBufferOf(int body, bool normals);
  /// The set that holds body b's surface on its device, up to date (enqueued), or nullptr on the
  /// host path; *member its index in the set.
  SurfaceSet* refreshSurface(Body& b, std::size_t* member);
  /// Makes the group's surface sets for its device as it is now (after a failover too).
  void ensureSurfaces(Group& g);
  nlohmann::json surfacePlanJson(const Body& b);

  // -- reports (reports.cpp)
  nlohmann::json batchJson(const Body& b) const;
  nlohmann::json batchesJson() const;
  nlohmann::json unbatchedJson() const;
};

}  // namespace corofem
