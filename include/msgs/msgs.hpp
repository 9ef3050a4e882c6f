// include/msgs/msgs.hpp
// Umbrella header: the public API of msgs.
#pragma once

#include "camera.hpp"
#include "gaussian.hpp"
#include "image.hpp"
#include "rasterize.hpp"
