// Fixture for the layer check's own test: core must not include train.
#pragma once
#include "desplat/train/trainer.hpp"
