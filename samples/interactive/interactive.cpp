// An application's frame loop, headless (issue 25's sample): SOFA's liver (596 tets) with its
// 2,194-vertex render surface, held at its right end by the scene; at 90 Hz the application grabs
// the left lobe with a handle and drags it along a scripted path (held exactly, then by a spring),
// pins it and lets go, pushes the
// body with a force, adds a second body and removes it, and reads the deformed surface back every
// frame, as a renderer would. Only the public API (corofem/corofem.hpp).
//
//   interactive [--out DIR] [--seconds S] [--backend auto|reference|opencl]
//
// Runs from the project root (the liver comes from ../shared/data); exit 0, 3 when a step failed,
// 77 when the liver is absent, 2 for bad arguments.
// Writes DIR/frames.csv (per frame: time, step, surface update and read-back in ms, PCG
// iterations, the handle's target and the grabbed nodes' centroid) and DIR/frame_NNNN.obj (the
// deformed surface with normals, every 45th frame); plot_interactive.py draws them and prints the
// median and 99th percentile of each time.
#include <corofem/corofem.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

int fail(const std::string& what, const corofem::Status& st) {
  std::cerr << "interactive: " << what << ": " << st.message() << '\n';
  return st.code() == corofem::ErrorCode::BadInput ? 2 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  std::string out = "out/interactive", backend = "auto";
  double seconds = 6.0;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out" && i + 1 < argc) out = argv[++i];
    else if (a == "--seconds" && i + 1 < argc) seconds = std::atof(argv[++i]);
    else if (a == "--backend" && i + 1 < argc) backend = argv[++i];
    else {
      std::cerr << "usage: interactive [--out DIR] [--seconds S] [--backend auto|reference|opencl]\n";
      return 2;
    }
  }
  if (!(seconds > 0.0)) {
    std::cerr << "interactive: --seconds must be > 0\n";
    return 2;
  }
  if (!std::ifstream("../shared/data/meshes/sofa/liver.msh")) {
    std::cerr << "interactive: ../shared/data/meshes/sofa/liver.msh is absent (run from the project root, with the "
                 "shared data folder beside it); skipping\n";
    return 77;
  }
  // The scene: the liver as samples/coupled_liver has it, open-ended, with no integrator given (an
  // open-ended analysis runs backward Euler: docs/embedding.md, "Defaults").
  const std::string text = R"({
    "name": "interactive_liver",
    "bodies": [{
      "name": "liver",
      "mesh": {"file": "../shared/data/meshes/sofa/liver.msh"},
      "surface": "../shared/data/meshes/sofa/liver-smooth.obj",
      "material": {"youngs_modulus": 3000, "poisson_ratio": 0.45, "density": 1, "rayleigh_mass": 1.0},
      "fixed": [{"box": {"min": [1.2, 0, -2], "max": [2, 6, 3]}}],
      "loads": [{"type": "gravity", "vector": [0, -9.81, 0]}]
    }],
    "analysis": {"type": "dynamic", "time_step": 0.011111, "steps": 0},
    "backend": ")" + backend + R"("
  })";
  corofem::Result<corofem::Scene> scene = corofem::parseScene(text, ".");
  if (!scene) return fail("scene", scene.status());
  const auto createStart = Clock::now();
  corofem::Result<corofem::Simulation> created = corofem::Simulation::create(scene.value());
  if (!created) return fail("create", created.status());
  corofem::Simulation& sim = created.value();
  const double createMs = msSince(createStart);
  std::filesystem::create_directories(out);
  std::ofstream csv(out + "/frames.csv");
  csv << "frame,time_s,step_ms,surface_ms,readback_ms,pcg_iterations,target_x,target_y,target_z,grab_x,grab_y,grab_z,"
         "status\n";

  const double hz = 90.0, dt = 1.0 / hz;
  const double grab[3] = {-4.2, 2.6, 0.5};
  corofem::HandleDesc hd;
  for (int k = 0; k < 3; ++k) hd.point[k] = grab[k];
  hd.radius = 0.6;
  corofem::Result<int> handle = sim.addHandle(hd);
  if (!handle) return fail("addHandle", handle.status());
  std::vector<std::uint32_t> held;  // the grabbed nodes (for the centroid column)
  {
    std::vector<double> x;
    sim.readPositions(0, x);
    for (std::size_t n = 0; n < x.size() / 3; ++n)
      if (std::hypot(x[3 * n] - grab[0], x[3 * n + 1] - grab[1], x[3 * n + 2] - grab[2]) <= hd.radius)
        held.push_back(static_cast<std::uint32_t>(n));
  }
  std::vector<double> x, surface;
  std::vector<float> normals;
  const long frames = std::lround(seconds * hz);
  long failed = 0;
  bool softened = false, pinned = false, released = false, pushedDone = false, extraDone = false;
  int extra = -1;  // the second body's index while it is there
  for (long f = 0; f < frames; ++f) {
    const double t = static_cast<double>(f) * dt;
    // The script: drag along a loop for 3 s, the lobe held exactly for 1.5 s and then by a spring
    // of 2000 N/m (it lags behind the target and swings); pin the lobe where it is (handle
    // removed); release the pin at 4 s and push the lobe down with a 0.02 N force for 0.5 s; then
    // let it swing.
    double target[3] = {grab[0], grab[1], grab[2]};
    if (t >= 1.5 && !softened) {
      sim.setHandleStiffness(handle.value(), 2000.0);
      softened = true;
    }
    if (t < 3.0) {
      const double a = 2.0 * M_PI * t / 3.0;
      target[0] += 0.6 * std::sin(a);
      target[1] += 1.0 * (1.0 - std::cos(a));
      target[2] += 0.6 * std::sin(2.0 * a);
      sim.moveHandle(handle.value(), target);
    } else if (!pinned) {
      sim.removeHandle(handle.value());
      sim.pinNodes(0, held);
      pinned = true;
    } else if (t >= 4.0 && !released) {
      sim.unpinNodes(0, held);
      corofem::AppliedForce push;
      for (int k = 0; k < 3; ++k) push.point[k] = grab[k];
      push.force[1] = -0.02;
      sim.setForces(0, {push});
      released = true;
    } else if (t >= 4.5 && released && !pushedDone) {
      sim.setForces(0, {});
      pushedDone = true;
    }
    // A second body arrives at 4.6 s (a small block dropped beside the liver) and leaves at 5.6 s.
    if (t >= 4.6 && extra < 0 && !extraDone) {
      corofem::BodyDesc block;
      block.name = "block";
      corofem::BoxSpec box;
      box.min = {-2.5, 6.0, -0.5};
      box.max = {-1.5, 6.5, 0.5};
      box.cells = {4, 2, 4};
      block.mesh.box = box;
      block.material.youngsModulus = 3000;
      block.material.poissonRatio = 0.3;
      block.material.density = 1;
      corofem::LoadDesc g;
      g.kind = corofem::LoadDesc::Kind::Gravity;
      g.vector = {0.0, -9.81, 0.0};
      block.loads.push_back(g);
      corofem::Result<int> added = sim.addBody(block);
      if (!added) return fail("addBody", added.status());
      extra = added.value();
    } else if (t >= 5.6 && extra >= 0) {
      const corofem::Status removed = sim.removeBody(extra);
      if (!removed) return fail("removeBody", removed);
      extra = -1;
      extraDone = true;
    }
    corofem::StepReport report;
    const auto s0 = Clock::now();
    const corofem::Status st = sim.step(dt, &report);
    const double stepMs = msSince(s0);
    if (!st) ++failed;
    const auto u0 = Clock::now();
    sim.updateSurface(0);  // on a device: the surface kernels; on the host: nothing yet
    const double surfaceMs = msSince(u0);
    const auto r0 = Clock::now();
    sim.readSurface(0, surface, &normals);
    const double readMs = msSince(r0);
    sim.readPositions(0, x);
    double c[3] = {0, 0, 0};
    for (std::uint32_t n : held)
      for (int k = 0; k < 3; ++k) c[k] += x[3 * n + static_cast<std::size_t>(k)] / static_cast<double>(held.size());
    csv << f << ',' << sim.time() << ',' << stepMs << ',' << surfaceMs << ',' << readMs << ',' << report.linearIterations
        << ',' << target[0] << ',' << target[1] << ',' << target[2] << ',' << c[0] << ',' << c[1] << ',' << c[2] << ','
        << (st ? "ok" : "failed") << '\n';
    if (f % 45 == 0 || f + 1 == frames) {
      corofem::SurfaceMesh m = *sim.restSurface(0);
      m.vertices = surface;
      m.normals = normals;
      char name[64];
      std::snprintf(name, sizeof name, "/frame_%04ld.obj", f);
      const corofem::Status w = corofem::writeSurfaceMesh(out + name, m);
      if (!w) return fail("writing a frame", w);
    }
  }
  csv.flush();
  if (!csv) {
    std::cerr << "interactive: could not write " << out << "/frames.csv\n";
    return 1;
  }
  std::cout << "interactive: " << frames << " frames at 90 Hz on " << sim.backendName() << " (" << sim.deviceName()
            << "), " << failed << " failed step(s); create " << createMs << " ms; frames in " << out << '\n';
  return failed == 0 ? 0 : 3;
}
