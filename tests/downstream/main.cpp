// tests/downstream/main.cpp: renders one Gaussian through the installed msgs package, and puts a
// legend (with its values where msgs::freetype is linked) under the picture.
#include <msgs/colormap.hpp>
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
  const msgs::Image<float> pic = msgs::with_legend(img, msgs::Colormap::diverging, -1.0f, 1.0f);
  std::printf("downstream: legend %s (%dx%d)\n", msgs::default_text() ? "with values" : "without values", pic.width,
              pic.height);
  if (pic.width != 32 || pic.height <= 32) return 1;
  return centre > 0.5f ? 0 : 1;
}
