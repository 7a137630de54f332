#pragma once
// itk::GradientVectorFlowImageFilter behind plain pointers, as the reference that tests and
// benchmarks compare organsmith's GVF with. ITK bundles its own Eigen, which cannot share a
// translation unit with the system Eigen of core/, so nothing here includes core headers.
// Not used by the pipeline: ITK's filter is ~70× slower than `gvf_jacobi`.

namespace organsmith::seg {

/// Runs ITK's filter on the gradient (fx, fy) of an edge map (w × h, x fastest, unit spacing)
/// with noise level μ for `iterations` steps and writes the field to (u, v). ITK ignores
/// SetTimeStep and uses Δt = 1 / (2^D μ) = 1 / (4μ) in 2-D; pass that step to `gvf_jacobi`
/// to compare like with like. Returns the time step ITK used.
double gvf_itk_reference(const float* fx, const float* fy, int w, int h, double mu, int iterations, float* u,
                         float* v);

}  // namespace organsmith::seg
