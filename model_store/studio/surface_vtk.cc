// The only file of the studio that includes VTK (heavy headers stay here).
#include "model_store/studio/surface.h"

#ifdef AVE_HAVE_VTK
#include <vtkCellArray.h>
#include <vtkFlyingEdges3D.h>
#include <vtkFloatArray.h>
#include <vtkImageData.h>
#include <vtkMarchingCubes.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#endif

namespace ave::studio {

#ifdef AVE_HAVE_VTK
bool VtkSurfaceAvailable() { return true; }

absl::StatusOr<SurfaceMesh> VtkIsoSurface(const std::vector<float>& field, const VoxelGrid& grid, float iso, bool flying_edges) {
  vtkNew<vtkImageData> image;
  image->SetDimensions(grid.size.x(), grid.size.y(), grid.size.z());
  const Eigen::Vector3d first = grid.origin_m + Eigen::Vector3d::Constant(0.5 * grid.voxel_m);
  image->SetOrigin(first.x(), first.y(), first.z());
  image->SetSpacing(grid.voxel_m, grid.voxel_m, grid.voxel_m);
  vtkNew<vtkFloatArray> scalars;
  scalars->SetNumberOfTuples(static_cast<vtkIdType>(field.size()));
  std::copy(field.begin(), field.end(), scalars->GetPointer(0));  // x fastest, as VTK stores images
  image->GetPointData()->SetScalars(scalars);
  vtkSmartPointer<vtkPolyData> out;
  if (flying_edges) {
    vtkNew<vtkFlyingEdges3D> fe;
    fe->SetInputData(image);
    fe->SetValue(0, iso);
    fe->ComputeNormalsOff();
    fe->ComputeGradientsOff();
    fe->ComputeScalarsOff();
    fe->Update();
    out = fe->GetOutput();
  } else {
    vtkNew<vtkMarchingCubes> mc;
    mc->SetInputData(image);
    mc->SetValue(0, iso);
    mc->ComputeNormalsOff();
    mc->ComputeGradientsOff();
    mc->ComputeScalarsOff();
    mc->Update();
    out = mc->GetOutput();
  }
  SurfaceMesh mesh;
  vtkPoints* points = out->GetPoints();
  if (!points) return mesh;  // no surface
  mesh.positions_m.resize(static_cast<size_t>(points->GetNumberOfPoints()));
  for (vtkIdType i = 0; i < points->GetNumberOfPoints(); ++i) {
    double p[3];
    points->GetPoint(i, p);
    mesh.positions_m[static_cast<size_t>(i)] = Eigen::Vector3f(static_cast<float>(p[0]), static_cast<float>(p[1]), static_cast<float>(p[2]));
  }
  vtkCellArray* polys = out->GetPolys();
  mesh.indices.reserve(static_cast<size_t>(polys->GetNumberOfCells()) * 3);
  vtkIdType npts = 0;
  const vtkIdType* pts = nullptr;
  for (polys->InitTraversal(); polys->GetNextCell(npts, pts);) {
    if (npts != 3) return absl::InternalError("surface: VTK returned a polygon of " + std::to_string(npts) + " points");
    if (pts[0] == pts[1] || pts[1] == pts[2] || pts[0] == pts[2]) continue;
    mesh.indices.insert(mesh.indices.end(), {static_cast<uint32_t>(pts[0]), static_cast<uint32_t>(pts[1]), static_cast<uint32_t>(pts[2])});
  }
  return mesh;
}
#else
bool VtkSurfaceAvailable() { return false; }

absl::StatusOr<SurfaceMesh> VtkIsoSurface(const std::vector<float>&, const VoxelGrid&, float, bool) {
  return absl::UnimplementedError("surface: this build has no VTK (install libvtk9-dev)");
}
#endif

}  // namespace ave::studio
