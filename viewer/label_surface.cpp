// A smoothed isosurface of one label, for views made before the meshing stage has run.

#include "viewer/label_surface.h"

#include "viewer/detail/vtk_scene.h"

#include <vtkCellArray.h>
#include <vtkDiscreteFlyingEdges3D.h>
#include <vtkImageData.h>
#include <vtkPoints.h>
#include <vtkWindowedSincPolyDataFilter.h>

#include <algorithm>

namespace organsmith {

SurfaceMesh label_surface(const LabelMap& labels, std::uint8_t label, const LabelSurfaceOptions& options) {
  using viewer_detail::Ptr;
  const auto& g = labels.grid;
  const int step = std::max(1, options.step_vox);
  // Bounding box of the label, so that the isosurface only walks the voxels near it.
  std::array<std::int64_t, 3> lo{g.size_vox[0], g.size_vox[1], g.size_vox[2]}, hi{-1, -1, -1};
  for (std::int64_t k = 0; k < g.size_vox[2]; ++k)
    for (std::int64_t j = 0; j < g.size_vox[1]; ++j) {
      const std::uint8_t* row = labels.labels.data() + g.offset(0, j, k);
      for (std::int64_t i = 0; i < g.size_vox[0]; ++i)
        if (row[i] == label) {
          lo = {std::min(lo[0], i), std::min(lo[1], j), std::min(lo[2], k)};
          hi = {std::max(hi[0], i), std::max(hi[1], j), std::max(hi[2], k)};
        }
    }
  SurfaceMesh out;
  if (hi[0] < 0) return out;

  // Mask with a one-sample empty border, so that the surface closes where the organ touches
  // the edge of the image. Sampled every `step` voxels in-plane (never across slices).
  const std::array<int, 3> st{step, step, 1};
  std::array<int, 3> n{};
  for (int a = 0; a < 3; ++a) n[a] = int((hi[a] - lo[a]) / st[a]) + 3;
  auto img = Ptr<vtkImageData>::New();
  img->SetDimensions(n[0], n[1], n[2]);
  img->AllocateScalars(VTK_UNSIGNED_CHAR, 1);
  auto* m = static_cast<unsigned char*>(img->GetScalarPointer());
  std::fill(m, m + std::size_t(n[0]) * n[1] * n[2], 0);
  for (int c = 1; c < n[2] - 1; ++c)
    for (int b = 1; b < n[1] - 1; ++b)
      for (int a = 1; a < n[0] - 1; ++a) {
        const std::int64_t i = lo[0] + std::int64_t(a - 1) * st[0], j = lo[1] + std::int64_t(b - 1) * st[1],
                           k = lo[2] + std::int64_t(c - 1) * st[2];
        if (g.contains(i, j, k) && labels.at(i, j, k) == label) m[a + std::size_t(n[0]) * (b + std::size_t(n[1]) * c)] = 1;
      }

  auto fe = Ptr<vtkDiscreteFlyingEdges3D>::New();
  fe->SetInputData(img);
  fe->SetValue(0, 1);
  fe->ComputeNormalsOff();
  fe->ComputeGradientsOff();
  fe->ComputeScalarsOff();
  vtkPolyData* pd = nullptr;
  Ptr<vtkWindowedSincPolyDataFilter> smooth;
  fe->Update();
  pd = fe->GetOutput();
  if (options.smoothing_iterations > 0 && pd->GetNumberOfPolys() > 0) {
    smooth = Ptr<vtkWindowedSincPolyDataFilter>::New();
    smooth->SetInputConnection(fe->GetOutputPort());
    smooth->SetNumberOfIterations(options.smoothing_iterations);
    smooth->SetPassBand(options.pass_band);
    smooth->BoundarySmoothingOff();
    smooth->FeatureEdgeSmoothingOff();
    smooth->NonManifoldSmoothingOn();
    smooth->NormalizeCoordinatesOn();
    smooth->Update();
    pd = smooth->GetOutput();
  }

  // Sample (a, b, c) ↔ voxel index lo + (a − 1, b − 1, c − 1) ∘ step → LPS.
  const Eigen::Matrix4d A = g.index_to_lps_affine();
  out.vertices_lps_mm.resize(std::size_t(pd->GetNumberOfPoints()));
  for (vtkIdType p = 0; p < pd->GetNumberOfPoints(); ++p) {
    double q[3];
    pd->GetPoint(p, q);
    Eigen::Vector4d ijk;
    for (int a = 0; a < 3; ++a) ijk[a] = double(lo[a]) + (q[a] - 1.0) * st[a];
    ijk[3] = 1.0;
    out.vertices_lps_mm[std::size_t(p)] = (A * ijk).head<3>();
  }
  vtkCellArray* polys = pd->GetPolys();
  out.triangles.reserve(std::size_t(polys->GetNumberOfCells()));
  const vtkIdType* ids = nullptr;
  vtkIdType npts = 0;
  for (polys->InitTraversal(); polys->GetNextCell(npts, ids);)
    if (npts == 3) out.triangles.push_back({std::int32_t(ids[0]), std::int32_t(ids[1]), std::int32_t(ids[2])});
  if (out.signed_volume_mm3() < 0)
    for (auto& t : out.triangles) std::swap(t[1], t[2]);
  return out;
}

}  // namespace organsmith
