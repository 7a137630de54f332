#include "segmentation/gvf_itk_reference.h"

#include <itkCovariantVector.h>
#include <itkGradientVectorFlowImageFilter.h>
#include <itkImage.h>
#include <itkImageRegionConstIterator.h>
#include <itkImageRegionIterator.h>

namespace organsmith::seg {

double gvf_itk_reference(const float* fx, const float* fy, int w, int h, double mu, int iterations, float* u,
                         float* v) {
  using Vec = itk::CovariantVector<float, 2>;
  using VecImage = itk::Image<Vec, 2>;
  auto in = VecImage::New();
  VecImage::RegionType region;
  region.SetSize({{static_cast<itk::SizeValueType>(w), static_cast<itk::SizeValueType>(h)}});
  in->SetRegions(region);
  in->Allocate();
  {
    itk::ImageRegionIterator<VecImage> it(in, region);
    std::size_t i = 0;
    for (it.GoToBegin(); !it.IsAtEnd(); ++it, ++i) {
      Vec g;
      g[0] = fx[i];
      g[1] = fy[i];
      it.Set(g);
    }
  }
  using Filter = itk::GradientVectorFlowImageFilter<VecImage, VecImage, double>;
  auto filter = Filter::New();
  filter->SetInput(in);
  filter->SetNoiseLevel(mu);
  filter->SetIterationNum(iterations);
  filter->Update();
  itk::ImageRegionConstIterator<VecImage> it(filter->GetOutput(), region);
  std::size_t i = 0;
  for (it.GoToBegin(); !it.IsAtEnd(); ++it, ++i) {
    u[i] = it.Get()[0];
    v[i] = it.Get()[1];
  }
  return filter->GetTimeStep();
}

}  // namespace organsmith::seg
