// tests/shared_trainers.hpp: the Trainer<G> types that several tests drive step by step, each
// compiled once. Trainer<G>'s training loop and evaluations are not inline, so a test that includes
// this header (and so sees the extern declarations) leaves them, the costliest code of such a test
// to compile, to the one unit that instantiates them.
#pragma once

#include <msgs/train.hpp>

namespace msgs {
// test_train, test_exposure, test_checkpoint; instantiated in shared_trainers.cpp.
extern template class Trainer<Gaussian<7, 1>>;
// test_train_parity; instantiated in examples/experiment_sh0.cpp, run_experiment<0>'s Joint trainer.
extern template class Trainer<Gaussian<7, 0>>;
}  // namespace msgs
