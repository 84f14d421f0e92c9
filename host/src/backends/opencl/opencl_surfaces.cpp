// The OpenCL device's render surfaces (device/device.hpp: DeviceSurfaces): a DeviceSurfaceGroup
// (backends/opencl/device_surface.hpp, kernels/opencl/surface_update.cl) over the engine's own position
// buffer, each member reading its body's nodes where the engine keeps them (from the segment's
// first node, in the device's numbering, relative to the body's centroid). No host round trip of
// the tet nodes.
#ifdef COROFEM_WITH_OPENCL

#include "backends/opencl/opencl_surfaces.hpp"

#include "backends/opencl/segment_engine.hpp"
#include "backends/opencl/device_surface.hpp"
#include "util/error.hpp"

#include <memory>
#include <vector>

namespace corofem::detail {

namespace {

class OpenCLSurfaces final : public DeviceSurfaces {
 public:
  OpenCLSurfaces(SegmentEngine& engine, const std::vector<SurfaceMember>& members, bool separateStreams)
      : engine_(engine) {
    // The bindings in the device's numbering where it has one of its own (the group copies them).
    std::vector<SurfaceBinding> remapped(members.size());
    std::vector<DeviceSurfaceGroup::Member> group;
    std::size_t nodes = 0;
    for (std::size_t m = 0; m < members.size(); ++m) {
      const DevicePositions where = engine.devicePositions(members[m].body);
      remapped[m] = *members[m].binding;
      if (where.deviceNode)
        for (std::uint32_t& n : remapped[m].nodes) n = where.deviceNode[n];
      group.push_back({&remapped[m], where.firstNode});
      nodes = std::max(nodes, where.firstNode + members[m].binding->tetNodeCount);
      bodies_.push_back(members[m].body);
    }
    DeviceSurfaceOptions o;
    o.doublePrecision = engine.positionsAreDouble();
    o.external = {GpuApi::OpenCL, engine.context().context(), engine.context().queue(), engine.context().device()};
    o.separateStreams = separateStreams;
    group_ = std::make_unique<DeviceSurfaceGroup>(group, nodes, o);
  }

  void update() override {
    std::vector<const double*> centroids;
    for (std::size_t body : bodies_) centroids.push_back(engine_.positionCentroid(body));
    group_->update(engine_.positionBuffer(), centroids);
  }
  void read(std::size_t member, float* positions, float* normals) override { group_->read(member, positions, normals); }
  GpuBuffer vertexBuffer(std::size_t member) const override { return group_->vertexBuffer(member); }
  GpuBuffer normalBuffer(std::size_t member) const override { return group_->normalBuffer(member); }
  bool separateStreams() const override { return group_->separateStreams(); }
  void finish() override { group_->finish(); }
  std::vector<DeviceBuffer> buffers() const override {
    std::vector<DeviceBuffer> out;
    for (const DeviceSurfaceBuffer& b : group_->buffers()) out.push_back({b.name, b.bytes});
    return out;
  }

 private:
  SegmentEngine& engine_;
  std::vector<std::size_t> bodies_;
  std::unique_ptr<DeviceSurfaceGroup> group_;
};

}  // namespace

std::unique_ptr<DeviceSurfaces> createOpenCLSurfaces(SegmentEngine& engine, const std::vector<SurfaceMember>& members,
                                                     bool separateStreams) {
  if (members.empty()) return nullptr;
  return std::make_unique<OpenCLSurfaces>(engine, members, separateStreams);
}

}  // namespace corofem::detail

#endif  // COROFEM_WITH_OPENCL
