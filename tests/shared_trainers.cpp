// tests/shared_trainers.cpp: the one instantiation of Trainer<Gaussian<7, 1>> that the tests share
// (see shared_trainers.hpp).
#include "shared_trainers.hpp"

namespace msgs {
template class Trainer<Gaussian<7, 1>>;
}  // namespace msgs
