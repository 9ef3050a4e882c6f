// tests/downstream/main.cpp: renders one Gaussian through the installed msgs package.
#include <msgs/msgs.hpp>

#include <cstdio>

int main() {
  msgs::GaussianModel<msgs::Gaussian<3, 0>> model(1);
  model.means = {0.f, 0.f, 3.f};
  model.log_scales = {-2.f, -2.f, -2.f};
  model.quats = {1.f, 0.f, 0.f, 0.f};
  model.opacity_logits = {2.f};
  model.sh = {1.f, 0.f, -1.f};
  msgs::Camera<float> cam;
  cam.width = cam.height = 32;
  cam.fx = cam.fy = 32.f;
  cam.cx = cam.cy = 16.f;
  msgs::Rasterizer<msgs::Gaussian<3, 0>> raster;
  const auto& img = raster.forward(model, cam);
  const float centre = img.at(16, 16, 0);
  std::printf("downstream: centre red = %.4f\n", centre);
  return centre > 0.5f ? 0 : 1;
}
