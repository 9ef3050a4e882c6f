// include/msgs/synth/geometry.hpp
// Ray-primitive intersection for the synthetic scene ray tracer: spheres, oriented boxes, vertical
// cylinders, horizontal discs and the ground plane. World axes: x east, y north, z up, metres.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace msgs::synth {

using Vec2f = Eigen::Vector2f;
using Vec3f = Eigen::Vector3f;
using Mat3f = Eigen::Matrix3f;

/// A ray o + t d with unit direction d, valid for t in (tmin, tmax).
struct Ray {
  Vec3f o = Vec3f::Zero();
  Vec3f d = Vec3f(0, 0, -1);
  float tmin = 1e-4f;
  float tmax = std::numeric_limits<float>::infinity();
};

/// Closest intersection found so far along a ray: distance, outward normal and the hit point in
/// the primitive's local frame (texture coordinates).
struct PrimHit {
  float t = std::numeric_limits<float>::infinity();
  Vec3f n = Vec3f::UnitZ();
  Vec3f local = Vec3f::Zero();
  int face = -1;  ///< which face of a box (0..5: -x, +x, -y, +y, -z, +z); -1 elsewhere
};

/// Sphere with centre c and radius r.
struct Sphere {
  Vec3f c = Vec3f::Zero();
  float r = 1.f;
};

/// Oriented box: centre, rotation whose columns are the local axes in world space, half extents.
struct Box {
  Vec3f c = Vec3f::Zero();
  Mat3f axes = Mat3f::Identity();
  Vec3f half = Vec3f::Ones();
};

/// Open vertical cylinder (no caps) standing on `base`, radius r, height h.
struct VCylinder {
  Vec3f base = Vec3f::Zero();
  float r = 0.1f, h = 1.f;
};

/// Horizontal disc at height c.z facing up.
struct Disc {
  Vec3f c = Vec3f::Zero();
  float r = 1.f;
};

/// Nearest root of |o + t d - c|^2 = r^2 in (tmin, tmax); the sphere is seen from both sides so
/// that shadow rays leaving a crown still behave.
inline bool intersect(const Sphere& s, const Ray& ray, PrimHit& hit) {
  const Vec3f oc = ray.o - s.c;
  const float b = oc.dot(ray.d);
  const float c = oc.squaredNorm() - s.r * s.r;
  const float disc = b * b - c;
  if (disc < 0.f) return false;
  const float sq = std::sqrt(disc);
  float t = -b - sq;
  if (!(t > ray.tmin)) t = -b + sq;
  if (!(t > ray.tmin) || !(t < ray.tmax) || !(t < hit.t)) return false;
  hit.t = t;
  hit.local = ray.o + t * ray.d;
  hit.n = (hit.local - s.c) / s.r;
  hit.face = -1;
  return true;
}

/// Cheap bounding test: does the ray pass within the sphere before tmax (no hit record)?
inline bool touches(const Sphere& s, const Ray& ray, float tmax) {
  const Vec3f oc = ray.o - s.c;
  const float b = oc.dot(ray.d);
  const float c = oc.squaredNorm() - s.r * s.r;
  if (c <= 0.f) return true;  // origin inside
  if (b > 0.f) return false;  // moving away
  const float disc = b * b - c;
  return disc >= 0.f && -b - std::sqrt(disc) < tmax;
}

/// Slab test in the box frame; local = hit point in box coordinates.
inline bool intersect(const Box& bx, const Ray& ray, PrimHit& hit) {
  const Vec3f o = bx.axes.transpose() * (ray.o - bx.c);
  const Vec3f d = bx.axes.transpose() * ray.d;
  float t0 = ray.tmin, t1 = std::min(ray.tmax, hit.t);
  int axis0 = -1, axis1 = -1;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-12f) {
      if (o[a] < -bx.half[a] || o[a] > bx.half[a]) return false;
      continue;
    }
    const float inv = 1.f / d[a];
    float tn = (-bx.half[a] - o[a]) * inv, tf = (bx.half[a] - o[a]) * inv;
    if (tn > tf) std::swap(tn, tf);
    if (tn > t0) { t0 = tn; axis0 = a; }
    if (tf < t1) { t1 = tf; axis1 = a; }
    if (t0 > t1) return false;
  }
  // Entering face when the origin is outside, exit face when inside.
  float t = t0;
  int axis = axis0;
  if (axis0 < 0) { t = t1; axis = axis1; }
  if (axis < 0 || !(t > ray.tmin) || !(t < ray.tmax) || !(t < hit.t)) return false;
  const Vec3f pl = o + t * d;
  Vec3f nl = Vec3f::Zero();
  nl[axis] = pl[axis] > 0.f ? 1.f : -1.f;
  hit.t = t;
  hit.local = pl;
  hit.n = bx.axes * nl;
  hit.face = 2 * axis + (pl[axis] > 0.f ? 1 : 0);
  return true;
}

/// Side wall of a vertical cylinder; local = (angle around the axis, height above base, 0).
inline bool intersect(const VCylinder& cy, const Ray& ray, PrimHit& hit) {
  const float ox = ray.o.x() - cy.base.x(), oy = ray.o.y() - cy.base.y();
  const float a = ray.d.x() * ray.d.x() + ray.d.y() * ray.d.y();
  if (a < 1e-12f) return false;
  const float b = ox * ray.d.x() + oy * ray.d.y();
  const float c = ox * ox + oy * oy - cy.r * cy.r;
  const float disc = b * b - a * c;
  if (disc < 0.f) return false;
  const float sq = std::sqrt(disc);
  for (float t : {(-b - sq) / a, (-b + sq) / a}) {
    if (!(t > ray.tmin) || !(t < ray.tmax) || !(t < hit.t)) continue;
    const float z = ray.o.z() + t * ray.d.z() - cy.base.z();
    if (z < 0.f || z > cy.h) continue;
    const float px = ox + t * ray.d.x(), py = oy + t * ray.d.y();
    hit.t = t;
    hit.n = Vec3f(px, py, 0.f) / cy.r;
    hit.local = Vec3f(std::atan2(py, px), z, 0.f);
    hit.face = -1;
    return true;
  }
  return false;
}

/// Horizontal disc, hit from above only (it lies on the ground); local = (x, y) relative to centre.
inline bool intersect(const Disc& dc, const Ray& ray, PrimHit& hit) {
  if (!(ray.d.z() < 0.f)) return false;
  const float t = (dc.c.z() - ray.o.z()) / ray.d.z();
  if (!(t > ray.tmin) || !(t < ray.tmax) || !(t < hit.t)) return false;
  const Vec3f p = ray.o + t * ray.d;
  const Vec2f q(p.x() - dc.c.x(), p.y() - dc.c.y());
  if (q.squaredNorm() > dc.r * dc.r) return false;
  hit.t = t;
  hit.n = Vec3f::UnitZ();
  hit.local = Vec3f(q.x(), q.y(), 0.f);
  hit.face = -1;
  return true;
}

/// Infinite ground plane z = 0, hit from above only; local = world point.
inline bool intersect_ground(const Ray& ray, PrimHit& hit) {
  if (!(ray.d.z() < 0.f)) return false;
  const float t = -ray.o.z() / ray.d.z();
  if (!(t > ray.tmin) || !(t < ray.tmax) || !(t < hit.t)) return false;
  hit.t = t;
  hit.n = Vec3f::UnitZ();
  hit.local = ray.o + t * ray.d;
  hit.local.z() = 0.f;
  hit.face = -1;
  return true;
}

}  // namespace msgs::synth
