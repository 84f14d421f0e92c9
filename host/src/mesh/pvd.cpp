// ParaView .pvd time-series collection. The whole file is rewritten on each write() (through a
// temporary file and a rename), so a simulation killed between steps leaves a readable series.
#include "mesh/text_writer.hpp"
#include "util/error.hpp"

#include <cmath>
#include <corofem/mesh.hpp>

namespace corofem {

Status PvdSeries::write() const {
  return detail::guard([&] {
    mesh::TextWriter w;
    w << "<?xml version=\"1.0\"?>\n"
      << "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  <Collection>\n";
    for (const Entry& e : entries_) {
      if (!std::isfinite(e.time))
        detail::fail(ErrorCode::BadInput, "cannot write ", path_, ": time ", e.time, " of '", e.file,
                     "' is not finite");
      w << "    <DataSet timestep=\"" << e.time << "\" group=\"\" part=\"0\" file=\"" << mesh::xmlEscape(e.file)
        << "\"/>\n";
    }
    w << "  </Collection>\n</VTKFile>\n";
    w.save(path_);
  });
}

}  // namespace corofem
