#include "nursing_bed/core/fe/fe_output.h"

#include <yaml-cpp/yaml.h>

#include <fstream>
#include <iomanip>
#include <stdexcept>

namespace nursing_bed {
namespace fe {
namespace {

std::ofstream openOrThrow(const std::string& path) {
  std::ofstream f(path);
  if (!f) throw std::runtime_error("cannot write " + path);
  f << std::setprecision(9);
  return f;
}

}  // namespace

void writeVtk(const std::string& path, const MembraneModel& model, const std::string& title) {
  std::ofstream f = openOrThrow(path);
  const Eigen::Matrix3Xd& x = model.positions();
  const auto& tris = model.mesh().triangles;
  const bool plate = model.plate().mode != PlateState::Mode::kNone;
  const int n = model.nodeCount(), extra = plate ? 4 : 0;
  f << "# vtk DataFile Version 3.0\n" << title << "\nASCII\nDATASET POLYDATA\nPOINTS " << n + extra << " double\n";
  for (int j = 0; j < n; ++j) f << x(0, j) << ' ' << x(1, j) << ' ' << x(2, j) << '\n';
  if (plate) {
    const double lo = x.row(0).minCoeff() - 0.01, hi = x.row(0).maxCoeff() + 0.01, h = model.plate().height_m;
    f << lo << ' ' << lo << ' ' << h << '\n'
      << hi << ' ' << lo << ' ' << h << '\n'
      << hi << ' ' << hi << ' ' << h << '\n'
      << lo << ' ' << hi << ' ' << h << '\n';
  }
  const std::size_t cells = tris.size() + (plate ? 1 : 0);
  f << "POLYGONS " << cells << ' ' << tris.size() * 4 + (plate ? 5 : 0) << '\n';
  for (const auto& t : tris) f << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << '\n';
  if (plate) f << "4 " << n << ' ' << n + 1 << ' ' << n + 2 << ' ' << n + 3 << '\n';
  const auto& r = model.elementResponses();
  f << "CELL_DATA " << cells << "\nSCALARS stretch_max double 1\nLOOKUP_TABLE default\n";
  for (std::size_t i = 0; i < tris.size(); ++i) f << (i < r.size() ? r[i].stretch_max : 1.0) << '\n';
  if (plate) f << "1\n";
  f << "SCALARS state int 1\nLOOKUP_TABLE default\n";
  for (std::size_t i = 0; i < tris.size(); ++i) f << (i < r.size() ? static_cast<int>(r[i].state) : 0) << '\n';
  if (plate) f << "-1\n";
  f << "SCALARS part int 1\nLOOKUP_TABLE default\n";
  for (std::size_t i = 0; i < tris.size(); ++i) f << model.mesh().part[i] << '\n';
  if (plate) f << "9\n";
}

void writeStructureTable(const std::string& path, const StructureTable& t) {
  YAML::Emitter e;
  e.SetDoublePrecision(9);
  e << YAML::BeginMap << YAML::Key << "description" << YAML::Value << YAML::DoubleQuoted << t.description;
  e << YAML::Key << "heights_m" << YAML::Value << YAML::Flow << t.heights_m;
  e << YAML::Key << "pressures_pa" << YAML::Value << YAML::Flow << t.pressures_pa;
  for (const auto& [name, grid] :
       {std::make_pair("volume_m3", &t.volume_m3), std::make_pair("plate_force_n", &t.plate_force_n)}) {
    e << YAML::Key << name << YAML::Value << YAML::BeginSeq;
    for (const auto& row : *grid) e << YAML::Flow << row;
    e << YAML::EndSeq;
  }
  e << YAML::EndMap;
  std::ofstream f = openOrThrow(path);
  f << "# FE-derived airbag structure (fe_airbag table; doc/fe_membrane.md).\n"
    << "# Rows: plate heights; columns: gauge pressures. volume_m3 = gas volume (paper eq. 11),\n"
    << "# plate_force_n = upward force of the film on the plate held at that height.\n"
    << e.c_str() << "\n";
  if (!f) throw std::runtime_error("cannot write " + path);
}

}  // namespace fe
}  // namespace nursing_bed
