// tests/test_undistort.cpp
// Tests for include/msgs/io/undistort.hpp: the lens model against hand-expanded formulas, its
// inverse, and image undistortion against an analytic scene.
#include <doctest/doctest.h>

#include <cmath>

#include "msgs/io/undistort.hpp"

namespace test_undistort {
using namespace msgs;
using namespace msgs::io;

namespace {

Distortion opencv(double k1, double k2, double k3, double k4, double p1, double p2) {
  Distortion d;
  d.model = Distortion::Model::opencv;
  d.k1 = k1; d.k2 = k2; d.k3 = k3; d.k4 = k4; d.p1 = p1; d.p2 = p2;
  return d;
}

Camera<float> test_camera() {
  Camera<float> c;
  c.width = 96; c.height = 72;
  c.fx = 80; c.fy = 78; c.cx = 47.5f; c.cy = 36.25f;
  return c;
}

// A smooth scene defined in undistorted pixel coordinates.
double scene(double u, double v) { return 0.5 + 0.25 * std::sin(0.11 * u) + 0.2 * std::cos(0.07 * v + 0.3); }

}  // namespace

TEST_CASE("OpenCV model matches the expanded polynomial") {
  const auto d = opencv(-0.12, 0.03, -0.004, 0.0007, 0.0015, -0.002);
  const double x = 0.3, y = -0.2;
  const double r2 = 0.13, r4 = r2 * r2, r6 = r4 * r2, r8 = r4 * r4;
  const double radial = 1 - 0.12 * r2 + 0.03 * r4 - 0.004 * r6 + 0.0007 * r8;
  const double ex = x * radial + 2 * 0.0015 * x * y + (-0.002) * (r2 + 2 * x * x);
  const double ey = y * radial + 0.0015 * (r2 + 2 * y * y) + 2 * (-0.002) * x * y;
  double xd, yd;
  d.distort(x, y, xd, yd);
  CHECK(xd == doctest::Approx(ex).epsilon(1e-14));
  CHECK(yd == doctest::Approx(ey).epsilon(1e-14));
}

TEST_CASE("fisheye model matches theta polynomial") {
  Distortion d;
  d.model = Distortion::Model::fisheye;
  d.k1 = 0.05; d.k2 = -0.01;
  const double x = 0.4, y = 0.3, r = 0.5, th = std::atan(r);
  const double thd = th * (1 + 0.05 * th * th - 0.01 * std::pow(th, 4));
  double xd, yd;
  d.distort(x, y, xd, yd);
  CHECK(xd == doctest::Approx(x * thd / r).epsilon(1e-14));
  CHECK(yd == doctest::Approx(y * thd / r).epsilon(1e-14));
}

TEST_CASE("rational model (COLMAP FULL_OPENCV) matches OpenCV's rational formula and inverts") {
  Distortion d;
  d.model = Distortion::Model::rational;
  d.k1 = -0.1; d.k2 = 0.02; d.k3 = -0.003; d.k4 = 0.05; d.k5 = -0.01; d.k6 = 0.002; d.p1 = 0.001; d.p2 = -0.0015;
  const double x = 0.3, y = -0.2, r2 = 0.13;
  const double radial = (1 - 0.1 * r2 + 0.02 * r2 * r2 - 0.003 * r2 * r2 * r2) / (1 + 0.05 * r2 - 0.01 * r2 * r2 + 0.002 * r2 * r2 * r2);
  double xd, yd;
  d.distort(x, y, xd, yd);
  CHECK(xd == doctest::Approx(x * radial + 2 * 0.001 * x * y - 0.0015 * (r2 + 2 * x * x)).epsilon(1e-14));
  CHECK(yd == doctest::Approx(y * radial + 0.001 * (r2 + 2 * y * y) + 2 * (-0.0015) * x * y).epsilon(1e-14));
  for (double px : {-0.5, 0.0, 0.4})
    for (double py : {-0.3, 0.2}) {
      double u, v, xu, yu;
      d.distort(px, py, u, v);
      REQUIRE(d.undistort(u, v, xu, yu));
      CHECK(xu == doctest::Approx(px).epsilon(1e-9));
      CHECK(yu == doctest::Approx(py).epsilon(1e-9));
    }
  CHECK_FALSE(d.is_identity());
  d.k1 = d.k2 = d.k3 = d.k4 = d.p1 = d.p2 = 0;
  CHECK_FALSE(d.is_identity());  // the denominator alone still distorts
  d.k5 = d.k6 = 0;
  CHECK(d.is_identity());
}

TEST_CASE("undistort inverts distort") {
  const auto d = opencv(-0.2, 0.05, 0.0, 0.0, 0.001, 0.002);
  for (double x : {-0.5, -0.1, 0.0, 0.25, 0.6})
    for (double y : {-0.4, 0.0, 0.3}) {
      double xd, yd, xu, yu;
      d.distort(x, y, xd, yd);
      REQUIRE(d.undistort(xd, yd, xu, yu));
      CHECK(xu == doctest::Approx(x).epsilon(1e-9));
      CHECK(yu == doctest::Approx(y).epsilon(1e-9));
    }
  Distortion none;
  CHECK(none.is_identity());
  CHECK(opencv(0, 0, 0, 0, 0, 0).is_identity());
}

TEST_CASE("a known point lands where the analytic model says after undistorting the image") {
  // Put a single bright pixel at the distorted location of an undistorted point P; after
  // undistortion the brightest pixel must be at P.
  const auto cam = test_camera();
  const auto d = opencv(-0.15, 0.02, 0, 0, 0.002, -0.001);
  const int pu = 70, pv = 18;  // target pixel in the undistorted image
  const double x = (pu + 0.5 - cam.cx) / cam.fx, y = (pv + 0.5 - cam.cy) / cam.fy;
  double xd, yd;
  d.distort(x, y, xd, yd);
  const double ud = cam.fx * xd + cam.cx, vd = cam.fy * yd + cam.cy;
  Image<float> distorted(cam.width, cam.height, 1);
  distorted.at(int(std::floor(ud)), int(std::floor(vd)), 0) = 1.0f;
  const auto out = undistort_image(distorted, cam, d);
  int bu = -1, bv = -1;
  float best = -1;
  for (int v = 0; v < out.height; ++v)
    for (int u = 0; u < out.width; ++u)
      if (out.at(u, v, 0) > best) { best = out.at(u, v, 0); bu = u; bv = v; }
  CHECK(std::abs(bu - pu) <= 1);
  CHECK(std::abs(bv - pv) <= 1);
  CHECK(best > 0.2f);
}

TEST_CASE("undistorting a synthetically distorted analytic image recovers the scene") {
  const auto cam = test_camera();
  const auto d = opencv(0.18, 0.04, 0, 0, 0.001, 0.0015);
  // Distorted image: pixel (ud, vd) sees the scene at the undistorted point that maps to it.
  Image<float> distorted(cam.width, cam.height, 2);
  for (int v = 0; v < cam.height; ++v)
    for (int u = 0; u < cam.width; ++u) {
      double x = 0, y = 0;
      REQUIRE(d.undistort((u + 0.5 - cam.cx) / cam.fx, (v + 0.5 - cam.cy) / cam.fy, x, y));
      const double us = cam.fx * x + cam.cx, vs = cam.fy * y + cam.cy;
      distorted.at(u, v, 0) = float(scene(us, vs));
      distorted.at(u, v, 1) = 1.0f - float(scene(us, vs));
    }
  Image<float> valid;
  const auto out = undistort_image(distorted, cam, d, &valid);
  double max_err = 0, naive_err = 0;
  int counted = 0;
  for (int v = 0; v < cam.height; ++v)
    for (int u = 0; u < cam.width; ++u) {
      if (valid.at(u, v, 0) == 0) continue;
      ++counted;
      const double want = scene(u + 0.5, v + 0.5);
      max_err = std::max(max_err, std::abs(out.at(u, v, 0) - want));
      max_err = std::max(max_err, std::abs(out.at(u, v, 1) - (1 - want)));
      naive_err = std::max(naive_err, std::abs(distorted.at(u, v, 0) - want));
    }
  CHECK(counted > cam.width * cam.height / 2);
  CHECK(max_err < 0.01);
  CHECK(naive_err > 0.05);  // the distortion is strong enough to matter
  // Pincushion distortion: the corners sample outside the source.
  CHECK(valid.at(0, 0, 0) == 0.0f);
}

TEST_CASE("zoomed undistorted camera keeps every output pixel inside the source") {
  const auto cam = test_camera();
  const auto d = opencv(0.18, 0.04, 0, 0, 0, 0);
  const auto z = undistorted_camera(cam, d, true);
  CHECK(z.fx > cam.fx);
  CHECK(z.fy / z.fx == doctest::Approx(cam.fy / cam.fx));
  Image<float> img(cam.width, cam.height, 1, 0.5f), valid;
  (void)undistort_image(img, cam, d, z, &valid);
  for (float m : valid.data) CHECK(m == 1.0f);
  // Barrel distortion samples inside the source already and needs no zoom.
  CHECK(undistorted_camera(cam, opencv(-0.1, 0, 0, 0, 0, 0), true).fx == cam.fx);
}

TEST_CASE("size mismatch between image and camera is an error") {
  Image<float> img(10, 10, 1);
  CHECK_THROWS_AS((void)undistort_image(img, test_camera(), Distortion{}), IoError);
}

}  // namespace test_undistort
