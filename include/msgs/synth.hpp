// include/msgs/synth.hpp
// The synthetic multi-spectral dataset generator: a procedural outdoor scene, a CPU ray tracer
// that gives its ground truth, a 5-camera drone rig, and a writer for the public dataset layout.
//
// Pipeline, one header per step (include/msgs/synth/):
//   noise.hpp    deterministic hashing, RNG and value noise
//   spectra.hpp  bands (D, MS_G, MS_R, MS_RE, MS_NIR) and material reflectances
//   geometry.hpp ray-primitive intersections
//   rig.hpp      presets, the camera rig and the flight pattern
//   scene.hpp    the scene, trace() and spectral shading
//   render.hpp   render_band() and the sparse point cloud
//   dataset.hpp  write_synthetic_dataset()
//
// Usage:
//   msgs::synth::SynthOptions opt;   // preset "tiny" | "small" | "medium", seed
//   auto summary = msgs::write_synthetic_dataset("data/synth", opt);
#pragma once

#include "synth/dataset.hpp"
#include "synth/geometry.hpp"
#include "synth/noise.hpp"
#include "synth/render.hpp"
#include "synth/rig.hpp"
#include "synth/scene.hpp"
#include "synth/spectra.hpp"
